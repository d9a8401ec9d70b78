"""Sphinx configuration of the course website (``make book``).

The site renders the committed notebooks as they are (the outputs nbval checked); nothing is
executed while it builds, and nothing is downloaded: Sphinx, MyST-NB and the book theme come
from PyPI with their assets.
"""

project = "ROS 2 architecture, live"
author = "the course authors"
copyright = "the course authors, Apache-2.0"

extensions = ["myst_nb"]
nb_execution_mode = "off"  # show the committed outputs; CI has checked them with strict nbval
# A widget needs JavaScript from the internet to draw itself on a static page. Every widget of the
# course carries a static record (text, HTML, a picture), so the site shows that instead.
nb_mime_priority_overrides = [("html", "application/vnd.jupyter.widget-view+json", None),
                              ("html", "application/vnd.jupyter.widget-state+json", None)]
nb_merge_streams = True
myst_enable_extensions = ["dollarmath"]
# A %%writefile cell holds the file it writes (09's package.xml, setup.cfg): the notebook's IPython lexer
# cannot read XML or INI, and Pygments then highlights the cell in its relaxed mode, which shows it whole.
suppress_warnings = ["mystnb.unknown_mime_type", "myst.header", "misc.highlighting_failure"]
exclude_patterns = ["_build", "**.ipynb_checkpoints"]

html_theme = "sphinx_book_theme"
html_title = "ROS 2 architecture, live"
html_theme_options = {
    "home_page_in_toc": True,
    "show_toc_level": 2,
    "use_download_button": True,
    "navigation_with_keys": True,
}
html_last_updated_fmt = None
html_copy_source = False
