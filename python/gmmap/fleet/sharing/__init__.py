"""The sharing protocol between robot nodes: what a node's stages pass on (`events`), adverts of
what each robot holds (`holdings`), what arrived (`arrivals`), fetching what is missing
(`fetching`), lingering until peers hold what we hold (`lingering`), what the node shares with
its fetcher and lingerer (`shared`) and the byte counts robots give on request (`linkstats`)."""
