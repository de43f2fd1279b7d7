"""A model file whose import fails."""

raise RuntimeError("this module cannot be imported")
