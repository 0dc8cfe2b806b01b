"""Every kernel of a step compiles for an H100 (sm_90), also on a machine without a GPU.

Warp carries its own CUDA compiler (NVRTC), so ahead-of-time compilation needs no driver: this
catches CUDA-only build errors (tile shapes, block widths, types) before a GPU ever runs the code.
It runs in a fresh interpreter so that the CUDA block widths set here never touch the CPU modules
the other tests use.
"""

import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent(
    """
    import tempfile, warp as wp
    import decco_warp
    from decco_warp.kernels import bodies, contacts, fused, integrate, neighbours, newton, observables, reference, tree

    kernels = []
    for precision in bodies.PRECISIONS:
        for ledger in (False, True):
            kernels += [(fused.pair_forces_tiled(128, 4, 4, precision, "paper", ledger, 128), 128),
                        (fused.pair_forces_tiled(64, 4, 4, precision, "paper-printed-rolling", ledger, 128), 64),
                        (reference.pair_forces_reference(precision, "paper"), 256),
                        (fused.pair_forces_tiled(128, 4, 4, precision, "ssdem", ledger, 128), 128),
                        (reference.pair_forces_reference(precision, "ssdem"), 256)]
        kernels += [(newton.pair_gravity_newton(2, precision), 32), (newton.gather_newton(precision), 256)]
        # Gravity on its own clock: the sweep and gather without candidates.
        kernels += [(newton.pair_gravity_newton(2, precision, 0, False), 32), (newton.gather_newton(precision, False), 256)]
    kernels += [(contacts.contact_pass(law, 8, 4, accumulate), 32) for law in ("paper", "paper-printed-rolling") for accumulate in (True, False)]
    kernels += [(contacts.contact_pass("ssdem", 1, 32, accumulate), 32) for accumulate in (True, False)] + [(contacts.copy_springs, 256)]
    kernels += [(neighbours.build_neighbour_list, 256)]  # (integrate's module holds kick_outer and kick_drift_inner)
    kernels += [(bodies.pack_bodies, 256), (integrate.kick_drift, 256), (observables.pair_observables, 256), (observables.pair_observables_tiled(128), 128),
                (observables.candidate_observables, 256), (tree.tree_gravity("mixed"), 256), (tree.tree_gravity("float64"), 256), (tree.tree_potential, 256),
                (tree.walk_records("mixed"), 256), (tree.walk_records("float64"), 256)]
    folder = tempfile.mkdtemp()
    for kernel, block_dim in kernels:
        kernel.module.options["block_dim"] = block_dim
        try:
            wp.compile_aot_module(kernel.module, arch=90, module_dir=folder)
        except Exception as error:
            text = str(error)
            if "NVRTC" in text or "nvrtc" in text or "not available" in text:
                print("SKIP", text.splitlines()[0]); raise SystemExit(0)
            print("FAILED", kernel.key, text); raise SystemExit(1)
    print("COMPILED", len(kernels))
    """
)


def test_every_kernel_compiles_for_sm90():
    import pytest

    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=900)
    output = done.stdout + done.stderr
    if "SKIP" in done.stdout:
        pytest.skip(f"Warp cannot compile for CUDA here: {done.stdout.strip()}")
    assert done.returncode == 0 and "COMPILED" in done.stdout, output[-3000:]
