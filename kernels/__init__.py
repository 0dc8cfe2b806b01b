"""Warp kernels of decco-warp (installed as ``decco_warp.kernels``).

``pair``: the physics of one pair as ``@wp.func`` pieces.  The all-pairs force/torque kernels
built from them, a module per layout: ``newton`` (each pair once, the CUDA default), ``fused``
(the CPU default) and ``reference`` (one thread per particle); ``bodies`` (the packed
particles their sweeps read) and ``contacts`` (contacts in float64, the contact pass of candidate
lists) are shared by all.  ``tree``: the tree path's gravity and contact candidates;
``integrate``: kick-drift-kick; ``observables``: per-particle energies, contacts and stress for
output.
Only :mod:`decco_warp.engine` launches these.
"""
