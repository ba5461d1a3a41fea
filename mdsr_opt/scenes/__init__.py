"""Scenes: the problem library's data model, node selection, the registry, scene files and the runner."""
