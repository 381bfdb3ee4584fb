"""Baker: displacement and normal maps from high/low-poly pairs, and model restoration (paper 003)."""
