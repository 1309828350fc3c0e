"""Command-line tools: each module has main(argv=None) and becomes colorglove_<name>."""
