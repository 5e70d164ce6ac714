"""Ingest: decoded recording messages → numpy columns / Arrow tables."""
