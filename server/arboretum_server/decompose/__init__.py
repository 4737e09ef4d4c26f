"""Decomposition of tree point clouds into Hierarchical Branch-Lobe (HBL) structures (VRTree section 3.4).

Entry point: ``pipeline.decompose(points, options)`` returns a ``Decomposition`` (the HBL plus the cached
graph arrays that make the refinement operations in ``refine`` fast); ``examples.make_examples`` turns
its HBL into library examples. Heavy dependencies are imported by the submodules, never here.
"""
