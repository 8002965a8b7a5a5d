"""MeshLab-style filters over pymeshlab.MeshSet (see issue: meshlab_filter)."""
