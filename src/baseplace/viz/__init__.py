"""Figures (matplotlib) and viewers; core modules never import this package."""
