"""The kernel switch ``$BBOXTUNE_JIT`` and the ``kernel`` decorator."""

import subprocess
import sys

import numpy as np
import pytest

from bboxtune.filters import jit


@pytest.mark.parametrize("value, expected", [("1", "True"), ("0", "False"), (" 1 ", "True")])
def test_switch_reads_the_environment(value: str, expected: str) -> None:
    out = subprocess.run([sys.executable, "-c", "from bboxtune.filters import jit; print(jit.enabled())"],
                         env={"BBOXTUNE_JIT": value, "PATH": ""}, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == expected


@pytest.mark.parametrize("value", ["yes", "2", "", "true"])
def test_bad_switch_value_is_named(value: str) -> None:
    out = subprocess.run([sys.executable, "-c", "from bboxtune.filters import jit"], env={"BBOXTUNE_JIT": value},
                         capture_output=True, text=True)
    assert out.returncode != 0
    assert "$BBOXTUNE_JIT" in out.stderr and "allowed 0" in out.stderr


def test_kernel_compiles_and_keeps_nan() -> None:
    @jit.kernel
    def running_sum(x):
        out = np.empty_like(x)
        s = 0.0
        for i in range(x.size):
            s += x[i]
            out[i] = s
        return out

    x = np.array([1.0, np.nan, 2.0])
    np.testing.assert_array_equal(running_sum(x), np.cumsum(x))
