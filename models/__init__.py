"""The robot library (robot files, YAML), installed as package data: see robstiff_drake/paths.py."""
