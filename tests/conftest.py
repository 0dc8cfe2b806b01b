import pytest

import decco_warp as dw
from decco_warp.device import cuda_device_count

DEVICES = ["cpu"] + [f"cuda:{i}" for i in range(cuda_device_count())]


@pytest.fixture(params=DEVICES)
def device(request):
    """Every device Warp finds here: the CPU always, CUDA too when present."""
    return request.param


@pytest.fixture
def paper_params():
    return dw.Params()
