"""Procedural growth inside lobes (VRTree section 3.5, Eq. 2): space colonization, pipe-model radii, leaves."""
