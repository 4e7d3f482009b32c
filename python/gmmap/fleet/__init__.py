"""The fleet runtime, a sub-package per concern: the wire format (`wire`), security
(`security`), the sharing protocol (`sharing`), the SQLite store (`storage`), the Zenoh
transport (`net`) and the nodes (`node`). Emulated links live outside it, in `gmmap.eval.links`."""
