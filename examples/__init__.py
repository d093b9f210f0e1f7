"""Example measurement campaigns (CSV), installed as package data: see robstiff_drake/paths.py."""
