"""Facts of the table-top domain (pure Python): palette, object categories and sizes, table bounds, named positions,
cameras. Modules: workspace, palette, objects, cameras."""
