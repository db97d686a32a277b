"""The `sfr` command line: the entry point, argument types and one module per subcommand."""
