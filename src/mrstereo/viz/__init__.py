"""Figures: matplotlib plumbing and the disparity colours every figure shares.

Conventions: docs/conventions.md.
"""
