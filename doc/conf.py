"""Sphinx configuration of the sma_wrist documentation (MyST Markdown, Read the Docs theme).

Builds under rosdoc2's rules (docs.ros.org): only ``sphinx.ext.*`` and ``myst_parser`` are used, and the
reference pages are written by the plain :func:`setup` hook below from the sources themselves (node parameter
specs, ``msg_defs/topics.yaml``, the ``sma-wrist`` argparse parsers, ``sma_wrist.core``'s docstrings) and the
validation page from ``doc/validation/results.json``, so none of them can drift from the code.

Build: ``sphinx-build -W --keep-going -b html doc doc/_build/html``.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

# This file's folder holds refgen.py. rosdoc2 execs a copy of this file from its wrapping conf.py (then __file__
# names the wrapper, and this folder is its doc/) with the package's sources first on sys.path.
_here = Path(__file__).resolve().parent
DOC = next((d for d in (_here, _here / 'doc', Path.cwd() / 'doc') if (d / 'refgen.py').is_file()), _here)
if (DOC.parent / 'package.xml').is_file():
    sys.path.insert(0, str(DOC.parent))  # the checkout's sma_wrist, also when an installed copy exists
sys.path.insert(0, str(DOC))  # refgen: the page generator (a module, not a Sphinx extension)

import refgen  # noqa: E402

project = 'sma_wrist'
author = 'sma_wrist developers'
copyright = 'sma_wrist developers, Apache-2.0'
release = refgen.version()
version = release

extensions = [
    'myst_parser',
    'sphinx.ext.autodoc',
    'sphinx.ext.autosummary',
    'sphinx.ext.napoleon',  # the numpy-style "Parameters / Returns" sections of sma_wrist.core
    'sphinx.ext.mathjax',
]
source_suffix = {'.md': 'markdown', '.rst': 'restructuredtext'}
root_doc = 'index'
exclude_patterns = ['_build']
myst_enable_extensions = ['colon_fence', 'dollarmath']
myst_heading_anchors = 3

# Every cross-reference must resolve; what points outside this package (numpy, scipy, the standard library's
# typing aliases) is not documented here, so only those are exempt.
nitpicky = True
nitpick_ignore_regex = [
    (r'py:.*', r'(numpy|np|scipy|numba|typing|collections|dataclasses|pathlib|argparse|enum|yaml|rclpy)(\..*)?'),
    (r'py:.*', r'(NDArray|ArrayLike|Path|Any|Callable|Sequence|Mapping|Iterable|Iterator|Self|optional)'),
    (r'py:class', r'(float|int|str|bool|dict|list|tuple|bytes|object|None|type|array|ndarray|function)'),
    (r'py:.*', r'sma_wrist\.(?!core\b).*'),  # the API reference is sma_wrist.core; the tools are commands
]

# every public name of a module, not only its __all__: the docstrings cross-reference the kernels' helpers
autodoc_default_options = {'members': True, 'ignore-module-all': True}
autodoc_member_order = 'bysource'
autodoc_typehints = 'none'  # the docstrings state types with their units; signatures stay readable
autosummary_generate = False  # refgen writes one page per module
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
napoleon_use_param = False  # types as text ("array_like, shape (N,)"), not as cross-references

html_theme = 'sphinx_rtd_theme'
html_title = 'sma_wrist'
html_theme_options = {'navigation_depth': 3}


def _generate(app) -> None:  # noqa: ANN001 - sphinx.application.Sphinx
    refgen.write_pages()  # into doc/: under rosdoc2 that is a folder below app.srcdir


# napoleon reads the text before the first colon of every attribute / data / property docstring as its type
# ("#: the thresholds r_j = c j [mm]: ..." became a cross-reference to a class "the thresholds ..."). This
# package documents those with reST prose (``#:`` comments), so napoleon sees them empty and they are restored
# right after it: napoleon still turns the numpy "Parameters / Attributes" sections of functions and classes.
_ATTRIBUTE_KINDS = ('attribute', 'data', 'property')
_held: dict[str, list[str]] = {}


def _hold_attribute_doc(app, what, name, obj, options, lines) -> None:  # noqa: ANN001
    if what in _ATTRIBUTE_KINDS:
        _held[name] = lines[:]
        lines[:] = []


def _restore_attribute_doc(app, what, name, obj, options, lines) -> None:  # noqa: ANN001
    if what in _ATTRIBUTE_KINDS and name in _held:
        lines[:] = _held.pop(name)


# The docstrings are written to be read in a terminal too (help(), the source): |x| is an absolute value there,
# which reST would read as a substitution. Outside ``literals`` and `roles` a bar is taken literally.
_LITERAL = re.compile(r'(``.+?``|:\w+:`[^`]+`|`[^`]+`_?)')


def _literal_bars(app, what, name, obj, options, lines) -> None:  # noqa: ANN001
    for i, line in enumerate(lines):
        if '|' in line:
            lines[i] = ''.join(
                part if k % 2 else part.replace('|', '\\|') for k, part in enumerate(_LITERAL.split(line))
            )


def setup(app):  # noqa: ANN001, ANN201
    # builder-inited runs before Sphinx collects the source files, so the written pages are read in this build
    app.connect('builder-inited', _generate)
    app.connect('autodoc-process-docstring', _hold_attribute_doc, priority=400)  # napoleon's runs at 500
    app.connect('autodoc-process-docstring', _restore_attribute_doc, priority=600)
    app.connect('autodoc-process-docstring', _literal_bars, priority=650)
    return {'parallel_read_safe': True}
