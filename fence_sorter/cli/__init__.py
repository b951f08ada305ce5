"""User command line of fence_sorter (``fence-sorter``): one module per subcommand."""
