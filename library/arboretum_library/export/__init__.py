"""File writers over plain arrays (numpy + the standard library only): glTF/GLB, OBJ + MTL, PLY, skeleton JSON."""
