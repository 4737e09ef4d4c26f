"""Arboretum's bottom layer: the HBL data model, wire protocol, example store and file readers.

numpy and light readers only: no GL, no open3d. Both applications (server, client) import it.
"""

__version__ = "0.1.0"
