"""The body: meshes, polygons, materials, muscles and mesh files."""
