"""The documentation (Markdown pages and their figures), installed as package data so that a wheel's
`robstiff examples --copy` can copy the pages its README points to: see robstiff_drake/paths.py."""
