"""The document of a diagnosis: `assemble` builds the content of DIR/diagnosis.json, `plots` the
visual proof as plain arrays (added-variable plots, located structure, the re-simulated campaign)."""
