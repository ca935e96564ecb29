"""studies/blas.py: which BLAS a process runs on, and the refusal to benchmark on the reference one."""

import pytest

from studies import blas

MAPS = """7f00-7f01 r--p 00000000 08:01 1 /usr/lib/x86_64-linux-gnu/libpetsc_real.so.3.18.1
7f01-7f02 r-xp 00000000 08:01 2 /usr/lib/x86_64-linux-gnu/{lib}
7f02-7f03 r--p 00001000 08:01 2 /usr/lib/x86_64-linux-gnu/{lib}
7f03-7f04 rw-p 00000000 00:00 0 [heap]
7f04-7f05 r-xp 00000000 08:01 3 /usr/lib/x86_64-linux-gnu/libcblas.so.3
"""


@pytest.mark.parametrize("path, kind", [
    ("/usr/lib/x86_64-linux-gnu/blas/libblas.so.3.11.0", "reference"),
    ("/usr/lib64/libblas.so.3.9.0", "reference"),
    ("/usr/lib/x86_64-linux-gnu/openblas-serial/libblas.so.3", "openblas"),
    ("/usr/lib/x86_64-linux-gnu/openblas-pthread/libopenblasp-r0.3.21.so", "openblas"),
    ("/opt/intel/lib/libmkl_rt.so.2", "mkl"),
    ("/usr/lib/x86_64-linux-gnu/blis-openmp/libblis.so.4", "blis"),
])
def test_classify_names_the_library(path, kind):
    assert blas.classify(path) == kind


def test_mapped_blas_reads_each_library_once_and_skips_other_files():
    libs = blas.mapped_blas(MAPS.format(lib="no-such-dir/libblas.so.3"))
    assert libs == ("/usr/lib/x86_64-linux-gnu/no-such-dir/libblas.so.3",)  # libcblas: a wrapper, not a BLAS
    assert blas.mapped_blas("7f03-7f04 rw-p 00000000 00:00 0 [heap]\n") == ()


def test_this_process_runs_on_a_known_blas():
    info = blas.detect()
    assert info.libraries and info.kind in blas.KINDS and info.kind != "unknown"
    assert info.kind in info.label()


def test_reference_blas_is_refused_unless_allowed(capsys):
    ref = blas.BlasInfo("reference", ("/usr/lib/x86_64-linux-gnu/blas/libblas.so.3.11.0",))
    assert not blas.require_optimized(ref, allow=False, what="bench")
    err = capsys.readouterr().err
    assert err.startswith("error: bench:") and err.count("\n") == 1 and blas.ALLOW_FLAG in err
    assert blas.require_optimized(ref, allow=True, what="bench")
    assert blas.require_optimized(blas.BlasInfo("openblas", ("/x/libopenblas.so.0",)), allow=False, what="bench")
    assert "reference" in blas.report_line(ref.as_dict()) and "not recorded" in blas.report_line(None)


@pytest.mark.serial
def test_bench_commands_refuse_to_measure_on_the_reference_blas(monkeypatch, tmp_path):
    """Exit code 2 before any case runs (the detection is replaced by a reference BLAS)."""
    from studies import bench, scaling

    ref = blas.BlasInfo("reference", ("/usr/lib/x86_64-linux-gnu/blas/libblas.so.3.11.0",))
    monkeypatch.setattr(blas, "detect", lambda load=True: ref)
    monkeypatch.setattr(scaling, "spawn", lambda *a, **k: pytest.fail("a case ran"))
    assert bench.main(["--sizes", "--no-output", "--no-reference", "--output", str(tmp_path)]) == 2
    assert bench.main(["--scaling", "--sizes", "2", "--output", str(tmp_path)]) == 2
    assert not (tmp_path / "bench.json").exists()


def test_compare_table_gives_ratios_to_the_first_library_and_every_run():
    def row(d, kind, threads, products, factors):
        return {"directory": d, "blas": {"kind": kind, "threads": threads}, "product_s": products, "factor_s": factors,
                "product_median_s": sorted(products)[1], "factor_median_s": sorted(factors)[1], "dofs": 36501,
                "norm_u": 42.3}
    rows = [row("system", "reference", None, [8.0, 9.0, 10.0], [30.0, 40.0, 50.0]),
            row("/x/openblas-serial", "openblas", 1, [0.4, 0.45, 0.5], [4.0, 5.0, 6.0])]
    text = blas.compare_table(rows, 22, 3, None)
    assert "| reference (system) | 1 | 9 | 1.00 | 40 | 1.00 | 8, 9, 10; 30, 40, 50 |" in text
    assert "| openblas (openblas-serial) | 1 | 0.45 | 0.05 | 5 | 0.12 |" in text and "36,501 dofs" in text


@pytest.mark.serial
def test_the_install_path_brings_openblas_and_unpins_the_reference_blas(tmp_path):
    """make system-packages (dry, SUDO=echo, every package 'installed' but OpenBLAS) installs libopenblas0-serial
    and sets an alternative left on netlib's library back to automatic."""
    import shutil
    import subprocess
    from pathlib import Path

    root = Path(__file__).parents[2]
    if shutil.which("make") is None or shutil.which("dpkg") is None:
        pytest.skip("needs make and dpkg")
    text = (root / "Makefile").read_text()
    assert "libopenblas0-serial" in text.split("APT_PACKAGES :=", 1)[1].split("\nifeq", 1)[0]
    fake = tmp_path / "bin"
    fake.mkdir()
    # dpkg -s says every package is there but OpenBLAS; readlink -f says the alternatives point to netlib's files
    (fake / "dpkg").write_text('#!/bin/sh\ncase "$2" in libopenblas*) exit 1;; esac\nexit 0\n')
    (fake / "readlink").write_text('#!/bin/sh\necho /usr/lib/x86_64-linux-gnu/blas/libblas.so.3.11.0\n')
    (fake / "ls").write_text('#!/bin/sh\necho libblas.so.3-x86_64-linux-gnu\n')
    for f in fake.iterdir():
        f.chmod(0o755)
    env = {"PATH": f"{fake}:/usr/bin:/bin", "HOME": str(tmp_path)}
    res = subprocess.run(["make", "-s", "system-packages", "SUDO=echo"], cwd=root, env=env, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    assert "apt-get install -y -qq --no-install-recommends libopenblas0-serial" in res.stdout
    assert "update-alternatives --quiet --auto libblas.so.3-x86_64-linux-gnu" in res.stdout
