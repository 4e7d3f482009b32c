"""A robot's store: the SQLite store (`store`), its record types (`records`) and rebuilding a
mapper from it after a restart (`reload`)."""
