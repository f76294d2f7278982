"""Exact scattering by canonical elastic objects, and what the simulator needs from it.

Modules
-------
bodies          what a scatterer is made of (Rigid, PressureRelease, Elastic, Shell; Fluid)
special         Bessel functions of all orders (recurrences) with derivatives
linear_systems  the batched, equilibrated solve of the per-order boundary systems
series          ModalCoefficients, truncation and band checks
modal           solid/fluid/rigid/soft cylinders (normal incidence) and spheres
shell           fluid-filled elastic cylindrical shells: exact and thin-shell
form_function   far-field form functions and cross-sections (optical theorem)
echo            per-row transfer functions of post and sphere echoes relative to today's rows
echo_series     the same for many rows from one coefficient table (what the simulator uses)
spectral_resampling  spectra of time-limited responses at any (scaled) frequencies: chirp-z
kernels         compiled loops: small linear systems, modal sums, Bessel recurrences
arrivals        the named internal arrivals (ground truth) and their delays
roughness       Kirchhoff (Eckart) coherent-reflection factor and its energy bookkeeping
"""
