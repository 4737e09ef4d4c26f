"""arboretum_server."""
