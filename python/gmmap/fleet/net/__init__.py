"""The transport over Zenoh: robots exchange opaque bytes (`transport.Transport`, its query side
in `querying`), on a session (`session`) under key expressions (`keys`), with their byte
counts (`counters`), callback workers (`worker`) and what waits to be sent (`outbox`)."""
