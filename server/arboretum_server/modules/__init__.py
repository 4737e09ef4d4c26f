"""Controllable modular trees (Takikawa et al., GI 2025): module skeletons, crowns, layer-by-layer growth."""
