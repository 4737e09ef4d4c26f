"""arboretum_client."""
