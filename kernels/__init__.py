"""Warp kernels of decco-warp (installed as ``decco_warp.kernels``).

``pair``: the physics of one pair as ``@wp.func`` pieces.  The all-pairs force/torque kernels
built from them, a module per layout: ``newton`` (each pair once, the CUDA default), ``fused``
(the CPU default) and ``reference`` (one thread per particle); ``bodies`` (the packed
particles their sweeps read) and ``contacts`` (contacts in float64, the contact pass of candidate
lists) are shared by all.  ``tree``: the tree path's gravity and contact candidates;
``integrate``: kick-drift-kick; ``observables``: per-particle energies, contacts and stress for
output.
Only :mod:`decco_warp.engine` launches these.

Every kernel's parameters come in groups under three headers, in this order, as MuJoCo Warp
groups its own: ``# Model:`` (what the run holds fixed: constants, the model's arrays such as radii,
masses and systems, the layout's tables), ``# In:`` (what the launch reads: the state, lists and
other arrays made by earlier launches, flags) and ``# Out:`` (what it writes).  An array's name
says what the kernel does with it: ``_in`` read, ``_out`` written (whatever it held before does not
matter), ``_inout`` read and written (kicked velocities, a box or depth record raised atomically);
scalars and structs of constants have no suffix.  A launch passes the ``# Model:`` and ``# In:``
groups as ``inputs=[...]`` and the ``# Out:`` group as ``outputs=[...]``, by position.
"""
