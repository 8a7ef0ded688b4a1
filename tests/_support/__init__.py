"""Helpers shared by test modules of several files (test modules never import each other).

Importable as ``_support`` because ``tests/conftest.py`` puts ``tests/`` on ``sys.path``.
"""
