"""Acquisition over serial ports: wire protocol, clock sync, crash-safe recording, virtual devices.

See docs/guide/acquire.md.  Pure cores: `protocol` (frames), `clock` (device → host time),
`session` (frames → recording), `devicesim.device_streams`; shells: `run` (ports, signals),
`devicesim.play` (ptys), `recover`.
"""
