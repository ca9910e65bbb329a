"""Compact BRDF models: families of models of at most N numbers per material (``families/``)."""
