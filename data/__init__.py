"""Published tables (CSV), installed as package data: see robstiff_drake/paths.py."""
