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
arrivals        the named internal arrivals (ground truth) and their delays
roughness       Kirchhoff (Eckart) coherent-reflection factor and its energy bookkeeping
"""
