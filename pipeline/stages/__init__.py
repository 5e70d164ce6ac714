"""The pipeline's stages (ingest → validate → identify → observe → diagnose → report) and
the runner that chains them with content-hash caching (see docs/reference/artefacts.md)."""
