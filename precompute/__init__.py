"""Command line that builds, lists, verifies and rebuilds shspec's cached Gaunt tables (``python -m precompute``)."""
