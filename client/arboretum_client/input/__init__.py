"""Input backends feeding the two-hands model: desktop (mouse and keyboard) and OpenXR."""
