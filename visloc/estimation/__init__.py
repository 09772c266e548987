"""Placeholder package: see the open issues for this layer."""
