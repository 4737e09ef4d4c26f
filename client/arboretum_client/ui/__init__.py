"""Hand-made 2D panels (Pillow), one module per panel, composed by layout.draw_ui."""
