"""Node designs: how nodes are made and how runs become coefficients."""
