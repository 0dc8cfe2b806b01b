"""Warp kernels of decco-warp (installed as ``decco_warp.kernels``).

``pair``: the physics of one pair as ``@wp.func`` pieces; ``forces``: the
all-pairs force/torque kernels built from them; ``integrate``: kick-drift-kick;
``observables``: per-particle energies, contacts and stress for output.
Only :mod:`decco_warp.engine` launches these.
"""
