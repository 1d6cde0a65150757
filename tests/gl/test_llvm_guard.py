"""GL first, then torch's optimiser and compile path, in one process: no crash.

With the registry's default torch (CUDA build, which brings triton), ``import triton`` after the first
Mesa EGL context killed the interpreter with a segmentation fault (two LLVMs, one process:
glradial/gl/llvm_guard.py). The test extras install triton, so this scenario runs the real library
here and in CI; each case runs in a fresh interpreter, since a crash must not take pytest with it
and the guard acts once per process, before the first context."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import textwrap

import pytest

pytest.importorskip("torch")

HAS_TRITON = importlib.util.find_spec("triton") is not None


def _run(code: str, timeout: float = 240.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=timeout)


def _explain(proc: subprocess.CompletedProcess) -> str:
    how = f"killed by signal {-proc.returncode}" if proc.returncode < 0 else f"exit status {proc.returncode}"
    return f"{how}\nstdout:\n{proc.stdout[-2000:]}\nstderr:\n{proc.stderr[-4000:]}"


def test_gl_context_then_torch_optimiser_and_compile_does_not_crash():
    proc = _run("""
        import importlib.util
        import numpy as np
        import glradial
        frame = np.full((48, 64, 3), 100, np.uint8)
        out = glradial.correct(frame, -0.2, 0.0, backend="gl")      # a Mesa EGL context now exists
        assert out.shape == frame.shape
        import torch
        model = torch.nn.Linear(4, 2)
        opt = torch.optim.Adam(model.parameters(), lr=1e-2)           # torch's optimisers probe triton lazily
        loss = model(torch.ones(3, 4)).pow(2).sum()
        loss.backward()
        opt.step()
        if importlib.util.find_spec("triton") is not None:
            import triton                                               # the import that used to segfault
            assert triton.__version__
        compiled = torch.compile(lambda x: torch.sin(x) * 2.0, backend="eager")   # dynamo's path
        assert torch.allclose(compiled(torch.ones(5)), torch.sin(torch.ones(5)) * 2.0)
        print("survived")
    """)
    assert proc.returncode == 0 and "survived" in proc.stdout, _explain(proc)


@pytest.mark.skipif(not HAS_TRITON, reason="triton is not installed (the test extras install it on Linux x86_64)")
def test_the_bundled_llvm_is_mapped_before_mesa_llvm_and_stays_local():
    """The guard maps triton's library before the context (so its LLVM binds to itself) and keeps its
    symbols out of the global scope (Mesa's LLVM must not bind to triton's either)."""
    proc = _run("""
        import ctypes
        import numpy as np
        import glradial
        glradial.correct(np.zeros((8, 8, 3), np.uint8), -0.1, 0.0, backend="gl")
        maps = [line.split()[-1] for line in open("/proc/self/maps") if line.rstrip().endswith(".so") or ".so." in line]
        import sys
        assert "triton" not in sys.modules, "the guard must not import triton's Python package"
        scope = ctypes.CDLL(None)
        print("mesa-llvm-global", hasattr(scope, "LLVMContextCreate"))
        print("triton-python-init-global", hasattr(scope, "PyInit_libtriton"))
        print("mapped", any("libtriton" in p for p in maps), any("libLLVM" in p for p in maps))
    """)
    assert proc.returncode == 0, _explain(proc)
    assert "mesa-llvm-global True" in proc.stdout, proc.stdout  # the hazard the guard exists for is real here
    assert "triton-python-init-global False" in proc.stdout, proc.stdout
    assert "mapped True True" in proc.stdout, proc.stdout


def test_guard_acts_once_and_ignores_packages_that_are_absent(monkeypatch):
    from glradial.gl import llvm_guard

    monkeypatch.setattr(llvm_guard, "_guarded", False)
    monkeypatch.setattr(llvm_guard, "BUNDLED_LLVM_LIBRARIES", (("glradial_no_such_package", "lib*.so"),))
    assert llvm_guard.guard_bundled_llvm() == []
    assert llvm_guard._guarded is True
    assert llvm_guard.guard_bundled_llvm() == []


def test_a_library_that_cannot_be_loaded_warns_with_the_fix(monkeypatch, tmp_path):
    from glradial.gl import llvm_guard

    package = tmp_path / "fakellvmpkg"
    (package / "_C").mkdir(parents=True)
    (package / "__init__.py").write_text("")
    (package / "_C" / "libfake.so").write_bytes(b"not an ELF file")
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setattr(llvm_guard, "_guarded", False)
    monkeypatch.setattr(llvm_guard, "BUNDLED_LLVM_LIBRARIES", (("fakellvmpkg", "_C/lib*.so"),))
    with pytest.warns(RuntimeWarning, match=r"import fakellvmpkg before using glradial's GL backend"):
        assert llvm_guard.guard_bundled_llvm() == []
