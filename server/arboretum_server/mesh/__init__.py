"""Whole-tree geometry: generalized-cylinder branch tubes, leaf cards and levels of detail."""
