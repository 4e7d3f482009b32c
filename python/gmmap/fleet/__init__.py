"""The fleet runtime: the wire codec, the Zenoh transport, the SQLite store and the robot node."""
