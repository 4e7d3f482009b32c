"""The wire format: the submap codec (`codec`, as `gmmap.encode` / `gmmap.decode`), its bit
packing (`bitstream`), quantisation (`quantise`) and anchors (`anchor`); docs/wire-format.md."""
