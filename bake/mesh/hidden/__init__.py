"""The hidden-geometry stage (``[mesh.hidden]``): keep what an eye in the view region sees.

``stage.py`` the entry point and the record; ``regions.py`` the eyes; ``visibility.py`` the rays;
``trim.py`` the cutting of crossing triangles (``mesh.hidden.trim``).
docs/hidden.md has the method, the decisions and the figures.
"""
