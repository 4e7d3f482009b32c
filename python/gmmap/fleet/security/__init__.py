"""Fleet security: credentials (`credentials`, over the CA in `authority` and the certificates
in `pki`), TLS and access control on the links (`access`), sealed messages (`seal`) and the
door every arriving message passes (`door`, with its limits in `guard`)."""
