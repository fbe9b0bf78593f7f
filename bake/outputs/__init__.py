"""What runs after the bake: writing its files (an atomic set with a manifest), report.json/.md,
report.html and its previews. The export stage (``bake.export``) makes the lists; this room puts
them, the project and the reports on disk."""
