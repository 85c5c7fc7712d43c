"""The machine of a bench run: CPU, torch threads and the fp32 matmul rate."""

from __future__ import annotations

import os
import platform
import time

import torch


def cpu_name() -> str:
    """CPU model from /proc/cpuinfo (Linux), else ``platform.processor()``."""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def matmul_gflops(m: int, k: int, n: int, repeats: int) -> float:
    """Best fp32 rate (GFLOP/s) of ``[m, k] @ [k, n]`` over ``repeats`` products."""
    a, b = torch.randn(m, k), torch.randn(k, n)
    out = torch.empty(m, n)
    torch.matmul(a, b, out=out)
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        torch.matmul(a, b, out=out)
        best = min(best, time.perf_counter() - t0)
    return 2 * m * k * n / best / 1e9


def machine_info(threads: int, shapes, repeats: int) -> dict:
    """CPU, torch threads, and the fp32 matmul rate: the best over ``shapes`` ([m, k, n]);
    also the rate of the first shape on one thread (to see whether the threads really run in
    parallel or the cores are busy with other work)."""
    rates = {f"{m}x{k}x{n}": matmul_gflops(m, k, n, repeats) for m, k, n in shapes}
    torch.set_num_threads(1)
    m, k, n = shapes[0]
    one_thread = matmul_gflops(m, k, n, repeats)
    torch.set_num_threads(threads)
    return {
        "cpu": cpu_name(),
        "threads": torch.get_num_threads(),
        "requested_threads": threads,
        "matmul_gflops": max(rates.values()),
        "matmul_by_shape": rates,
        "matmul_gflops_1_thread": one_thread,
        "torch": torch.__version__,
        "python": platform.python_version(),
        "loadavg_start": os.getloadavg()[0],
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY", "unset (spin, then sleep)"),
        "gomp_spincount": os.environ.get("GOMP_SPINCOUNT", "unset (300000)"),
    }
