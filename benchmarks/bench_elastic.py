"""Cost of the exact elastic series for the simulator: 1,000 frequency bins x 3 channels.

Usage
-----
    python benchmarks/bench_elastic.py [--repeats 7] [--bins 1000]

Prints the median wall time (s) over ``--repeats`` runs, measured in this run, of:
  - the modal coefficients of a solid PVC cylinder and sphere (all orders, all bins: the
    batched 3 x 3 solves), of a PVC pipe (6 x 6) and of the thin-shell model (4 x 4);
  - the post and sphere echo transfer functions of three rows (left, centre, right channel of
    the thesis tank's sonar at 1 m), coefficients included;
  - as a same-run reference, scipy.special.jv over the same (bins x orders) grid (the cost the
    recurrences in acoustisim.scattering.special avoid), and the ratio to it.
Band: 100 kHz - 1.2 MHz (the synthesiser's bins above -100 dB for the 5 us pulse).
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from scipy import special

from acoustisim.materials import get_material
from acoustisim.scattering.bodies import Fluid, Shell, body_from_material
from acoustisim.scattering.echo import EchoGeometry, EchoTarget, echo_transfer
from acoustisim.scattering.modal import modal_coefficients
from acoustisim.scattering.shell import shell_coefficients, thin_shell_coefficients


def median_time(function, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--bins", type=int, default=1000)
    args = parser.parse_args()
    water = Fluid(998.2, 1482.4)
    pvc = get_material("pvc")
    solid = body_from_material(pvc)
    pipe = Shell(solid, 0.003, Fluid(1.2, 343.0))
    f = np.linspace(100e3, 1.2e6, args.bins)
    radius = 0.025
    head = np.array([[0.0, -1.0, 0.5]] * 3)
    receivers = np.array([[-0.065, -1.0, 0.5], [0.0, -1.0, 0.5], [0.065, -1.0, 0.5]])
    post_rows = EchoGeometry.from_points(head, receivers, [0.0, radius, 0.5], [0.0, 0.0, 1.0])
    sphere_rows = EchoGeometry.from_points(head, receivers, [0.0, radius, 0.5])
    orders = modal_coefficients("cylinder", solid, radius, f, water).orders
    x = 2 * np.pi * f / water.sound_speed_m_s * radius
    cases = {
        "scipy jv, bins x orders (reference)": lambda: special.jv(orders[None, :], x[:, None]),
        "cylinder coefficients (PVC, 3x3)": lambda: modal_coefficients("cylinder", solid, radius, f, water),
        "sphere coefficients (PVC, 3x3)": lambda: modal_coefficients("sphere", solid, radius, f, water),
        "pipe coefficients (PVC/air, 6x6)": lambda: shell_coefficients(pipe, radius, f, water),
        "thin-shell coefficients (4x4)": lambda: thin_shell_coefficients(pipe, radius, f, water),
        "post echo transfer, 3 rows": lambda: echo_transfer(EchoTarget("post", radius, solid, pvc), post_rows, water, f),
        "sphere echo transfer, 3 rows": lambda: echo_transfer(EchoTarget("sphere", radius, solid, pvc), sphere_rows,
                                                              water, f),
    }
    print(f"{args.bins} bins, {orders.size} orders (ka up to {x.max():.1f}), median of {args.repeats} runs")
    reference = None
    for name, function in cases.items():
        function()  # warm-up
        seconds = median_time(function, args.repeats)
        reference = reference or seconds
        print(f"  {name:40s} {seconds * 1e3:9.1f} ms   x{seconds / reference:6.2f} of scipy jv")


if __name__ == "__main__":
    main()
