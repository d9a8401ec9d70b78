"""The maintainers' and students' programs around the course (``make lab``, ``make release``, the book,
the container image), importable as ``tools.x`` from anywhere: the repository's root is on the venv's
``sys.path`` (the editable install is one path in a ``.pth`` file; ``pyproject.toml``'s ``package-dir``).

Each program still runs as ``python tools/x.py`` (or ``python -m tools.x``), as the Makefile, the README
and the docs show.
"""
