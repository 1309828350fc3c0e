"""Nearest-neighbour pose lookup (paper section 4): distance, codes, database, search, blend."""
