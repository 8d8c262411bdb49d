"""bboxtune.filters.allocator: glibc's malloc set once per process to keep freed memory, unless told not to."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from bboxtune.filters import allocator


def _run(code: str, env_value: str | None) -> subprocess.CompletedProcess[str]:
    env = {"PATH": "/usr/bin:/bin"}
    if env_value is not None:
        env[allocator.ENV_VAR] = env_value
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt: Linux")
def test_a_batch_of_envs_sets_malloc_and_a_repeated_step_faults_few_pages_in() -> None:
    """In a fresh process: making the batched env sets malloc (True); then a step of 64 envs × 500 frames faults in
    almost no page (its freed arrays are reused, not mapped afresh: ~0.5 a step measured, against ~1,200 with
    ``$BBOXTUNE_MALLOC=default``)."""
    code = ("import json, resource, numpy as np\n"
            "from bboxtune.envs.vector import TuneBatch\n"
            "from bboxtune.filters import allocator\n"
            "b = TuneBatch(64, backend='ufir_cmn', track_length=500); b.seed(0); b.reset()\n"
            "a = np.zeros((64, b.env.action_map.dim), np.float32)\n"
            "for _ in range(3): b.step(a); b.reset()\n"
            "f = resource.getrusage(resource.RUSAGE_SELF).ru_minflt\n"
            "for _ in range(5): b.step(a); b.reset()\n"
            "print(json.dumps([allocator.keep_freed_memory(), (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f) / 5]))\n")
    done = _run(code, None)
    assert done.returncode == 0, done.stderr
    is_set, faults = json.loads(done.stdout.splitlines()[-1])
    assert is_set is True and faults < 200


def test_default_leaves_malloc_alone() -> None:
    done = _run("from bboxtune.filters import allocator; print(allocator.keep_freed_memory())", "default")
    assert done.returncode == 0 and done.stdout.strip() == "False"


@pytest.mark.parametrize("text", ["", "yes", "Tuned", "0"])
def test_a_bad_choice_is_refused_naming_the_variable(text: str, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(allocator.ENV_VAR, text)
    with pytest.raises(ValueError, match=rf"\${allocator.ENV_VAR}=.*allowed tuned, default"):
        allocator.keep_freed_memory()
