"""Sphinx configuration: the user guide (Markdown, read by myst-parser) and the API
reference generated from the numpydoc docstrings (autodoc + autosummary + napoleon).

Strict where it matters: ``nitpicky`` makes every cross-reference to nscd that does not
resolve a warning (``-W`` turns it into an error), while references into other projects
(numpy, scipy, the standard library: no network for intersphinx) are not checked.
Docstring style is not checked beyond what napoleon needs to parse the sections.
"""
from __future__ import annotations

import importlib
import os
import re
import sys

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
sys.path.insert(0, ROOT)

import nscd  # noqa: E402

project = "nscd"
author = "the nscd authors"
release = version = nscd.__version__
copyright = "nscd authors"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store"]
templates_path = ["_templates"]

# Markdown pages as they are: heading anchors for [text](#anchor) links, $...$ maths.
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]

# API reference
autosummary_generate = True
autosummary_imported_members = False
autosummary_ignore_module_all = True    # every public member (and submodule) of a module
autodoc_default_options = {"members": True, "undoc-members": True, "ignore-module-all": True,
                           "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
autoclass_content = "class"
autodoc_inherit_docstrings = False   # not the standard library's docstrings of overridden methods
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_ivar = True            # Attributes as fields: no second description of a dataclass field
napoleon_preprocess_types = False   # "float, optional" stays text: style is not policed

# Broken references fail the build; references outside nscd are not checked.
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(?!nscd\b).*"),        # numpy, scipy, builtins, typing ...
    (r"py:.*", r"(.*\.)?_[A-Za-z].*"),  # private helpers named in prose: not in the reference
]

# An unqualified name that several classes define (``shape``, ``dim`` in a type) links to
# the first: not a broken reference.
suppress_warnings = ["ref.python"]

html_theme = "alabaster"
html_static_path: list[str] = []
html_title = f"nscd {release}"


def _resolve_reexport(app, env, node, contnode):
    """Resolve a name re-exported by a package (``nscd.Scene``, ``nscd.solver.solve_velocity``)
    to the module that defines it; anything else stays unresolved (and fails the build)."""
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "").lstrip("~")
    parts = target.split(".")
    if parts[0] != "nscd":
        return None
    for split in range(len(parts) - 1, 0, -1):     # longest importable module prefix
        try:
            obj = importlib.import_module(".".join(parts[:split]))
        except ImportError:
            continue
        try:
            for attribute in parts[split:split + 1]:
                obj = getattr(obj, attribute)
        except AttributeError:
            return None
        module = getattr(obj, "__module__", None)
        name = getattr(obj, "__qualname__", None)
        if not module or not name or f"{module}.{name}" == ".".join(parts[:split + 1]):
            return None
        full = ".".join([module, name, *parts[split + 1:]])
        return env.get_domain("py").resolve_xref(env, node.get("refdoc"), app.builder,
                                                 node.get("reftype"), full, node, contnode)
    return None


# |x| in a docstring is an absolute value, not a reStructuredText substitution: escaped
# outside literals and roles (``...``, :math:`...`).
_CODE_SPAN = re.compile(r"(``.*?``|`[^`]*`)")
_ABSOLUTE = re.compile(r"(?<![\\|\w])\|(?=[^\s|])([^|`\n]*?[^\s|\\])\|(?![_|\w])")


def _escape_absolute_values(app, what, name, obj, options, lines):
    for i, line in enumerate(lines):
        parts = _CODE_SPAN.split(line)
        parts[::2] = [_ABSOLUTE.sub(r"\\|\1\\|", part) for part in parts[::2]]
        lines[i] = "".join(parts)


def _top_level_names(app, docname, source):
    """Fill the ``%% nscd-top-level-names`` line of the API page with a table of every name
    ``import nscd`` exports (``nscd.Scene``, ``nscd.simulate`` ...), linked to its module."""
    marker = "% nscd-top-level-names"
    if docname != "api" or marker not in source[0]:
        return
    rows = "\n".join(f"   nscd.{name}" for name in sorted(nscd._EXPORTS, key=str.lower))
    table = f"```{{eval-rst}}\n.. autosummary::\n\n{rows}\n```"
    source[0] = source[0].replace(marker, table)


def setup(app):
    app.connect("source-read", _top_level_names)
    app.connect("missing-reference", _resolve_reexport)
    app.connect("autodoc-process-docstring", _escape_absolute_values)
