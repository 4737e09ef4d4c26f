"""Example-based assembly (VRTree section 3.5): session state with undo/redo and autosave, the edit
operations (select, transform example, transform lobe, sketch, delete), recombination of placed examples
by Algorithm 1, and ``assembly_to_hbl`` turning an assembly into the one HBL that growth and export use."""
