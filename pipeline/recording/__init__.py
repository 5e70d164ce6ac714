"""The recording format: MCAP, JSON messages with JSON Schemas, metadata for models and fixtures."""
