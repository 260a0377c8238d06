"""What a benchmark ran on, in one place: the device JAX computes on (a GPU row must say which
card), the host's cores and load, and the suffix that keeps a GPU run's results beside the CPU
run's instead of over them."""

from __future__ import annotations

import os

import jax


def describe() -> dict:
    d = jax.devices()[0]
    return {
        "platform": d.platform,
        "device_kind": d.device_kind,
        "device_count": jax.device_count(),
        "host_cores": os.cpu_count(),
        "load_1min": os.getloadavg()[0],
        "jax": jax.__version__,
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }


def label(info: dict) -> str:
    """One line for a table's header: 'gpu: NVIDIA H100 80GB HBM3 (host 16 cores, load 0.3)'."""
    return (
        f"{info['platform']}: {info['device_kind']} x{info['device_count']} "
        f"(host {info['host_cores']} cores, load {info['load_1min']:.1f}, jax {info['jax']})"
    )


def suffix(info: dict) -> str:
    """'' on the CPU, '_gpu' (the platform's name) elsewhere."""
    return "" if info["platform"] == "cpu" else f"_{info['platform']}"
