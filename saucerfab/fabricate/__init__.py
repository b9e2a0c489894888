"""Fabrication: solid, UV atlas and bake, printer profiles, exporters.

This package's ``__init__`` stays light (no mesh libraries, no torch) so that
``saucerfab.fabricate.profiles`` can be used by the checker, which must start fast.
"""
