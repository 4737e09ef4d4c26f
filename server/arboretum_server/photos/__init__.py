"""Trees from photographs: structure from motion with pycolmap, then the tree isolated, oriented and scaled.

``reconstruct.reconstruct`` runs SIFT extraction, matching and incremental mapping on the CPU (dense
patch-match stereo only where pycolmap was built with CUDA); ``colmap_import.read_model`` reads an
existing COLMAP reconstruction instead; ``isolate.isolate`` removes the ground plane, keeps the main
cluster, turns the ground normal to +Z and scales the tree to a height (VRTree: 0.8 m), ready for
``decompose``. pycolmap is imported inside the submodules, never here.
"""
