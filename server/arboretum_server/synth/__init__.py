"""Synthetic trees with ground truth: guiding-vector graphs, the harmonic species model, a virtual scanner."""
