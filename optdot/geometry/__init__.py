"""The panel and the map: density field, domain (outline, holes, keep-outs), outline files,
the compiled edge index, Morton order."""
