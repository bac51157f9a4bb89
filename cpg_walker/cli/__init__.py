"""The `cpg-walker` command line."""
