"""Warm-up of a working arm and the temperature sensor that logs it (simulator side).

While the arm works its links and the jig warm as a first-order system,
ΔT(t) = ΔT∞·(1 − exp(−t/τ)), t since the start of the campaign.  The injected
`thermal_drift` then moves the true tip by g·ΔT(t) (g in m/K per axis of {W}) instead of
v·t — the expansion of the structure follows the temperature, not the clock.  With a
sensor, readings of the true temperature (ambient + ΔT, Gaussian noise, 0.01 K resolution)
go to the `/arm/temperature` channel at a fixed rate.  Shared by the arc-welder and Delta
simulators.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.ingest.temperature import TEMPERATURE

AMBIENT_K = 293.15  # 20 °C


@dataclass(frozen=True)
class WarmUp:
    """First-order warm-up: time constant τ (s), final rise ΔT∞ (K), ambient (K)."""

    tau_s: float
    rise_k: float
    ambient_k: float = AMBIENT_K

    def rise(self, t_s: np.ndarray) -> np.ndarray:
        """ΔT(t) (K) at times t (s since the start of the campaign)."""
        t = np.maximum(np.asarray(t_s, float), 0.0)
        return self.rise_k * -np.expm1(-t / self.tau_s)


@dataclass(frozen=True)
class Sensor:
    """A temperature sensor: name, where it is mounted, rate (Hz), noise σ (K), resolution (K)."""

    name: str = "link2"
    location: str = "upper arm (link 2), near J3"
    rate_hz: float = 1.0
    noise_k: float = 0.05
    resolution_k: float = 0.01


def parse_warm_up(text: str) -> WarmUp | None:
    """``TAU_S,DT_K`` (e.g. ``900,6``) → WarmUp; '' → None; ValueError otherwise."""
    if not text.strip():
        return None
    try:
        tau, dt = (float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"--warm-up {text!r}: expected TAU_S,DT_K (time constant s, final rise K), e.g. 900,6") from None
    if not (tau > 0 and np.isfinite(tau) and np.isfinite(dt)):
        raise ValueError(f"--warm-up {text!r}: the time constant must be > 0 s and the rise finite")
    return WarmUp(tau, dt)


@dataclass(frozen=True)
class Readings:
    """What the sensor logged: times (ns since epoch), temperatures (K)."""

    sensor: Sensor
    t_ns: np.ndarray
    kelvin: np.ndarray

    def stream(self):
        """As the ingest's `TemperatureStream` (what reading the recorded channel yields)."""
        from pipeline.ingest.temperature import TemperatureStream

        return TemperatureStream(self.sensor.name, self.sensor.location, self.t_ns, self.kelvin,
                                 np.arange(self.t_ns.size))

    def messages(self) -> list[tuple[str, dict]]:
        """(topic, body) events of the `/arm/temperature` channel."""
        return [(TEMPERATURE, {"timestamp_ns": int(t), "sensor": self.sensor.name, "location": self.sensor.location,
                               "temperature_k": float(k)}) for t, k in zip(self.t_ns, self.kelvin)]


def read_sensor(warm: WarmUp | None, t0_ns: int, t1_ns: int, rng: np.random.Generator,
                sensor: Sensor = Sensor()) -> Readings:
    """Readings from t0 to t1 (ns) at the sensor rate; without a warm-up the temperature stays
    at ambient (only the sensor noise)."""
    t_ns = np.arange(int(t0_ns), int(t1_ns) + 1, int(round(1e9 / sensor.rate_hz)), dtype=np.int64)
    true = AMBIENT_K + (warm.rise((t_ns - t0_ns) * 1e-9) if warm is not None else 0.0)
    k = true + rng.normal(0.0, sensor.noise_k, t_ns.size)
    k = np.round(k / sensor.resolution_k) * sensor.resolution_k
    return Readings(sensor, t_ns, np.round(k, 6))
