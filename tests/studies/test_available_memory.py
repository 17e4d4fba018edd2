"""The memory the size rule judges against is what this process may take: the smallest
of the host's available memory, its control group's limit and its address-space limit
(gearjax/_studies/resources.py)."""

import subprocess
import sys
import textwrap

from gearjax._studies import resources as _resources

GB = 1024**3


def write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_cgroup_v2_limit_less_usage(tmp_path):
    write(tmp_path / "proc_cgroup", "0::/job/42\n")
    write(tmp_path / "cg/job/42/memory.max", f"{10 * GB}\n")
    write(tmp_path / "cg/job/42/memory.current", f"{3 * GB}\n")
    assert _resources.cgroup_memory(str(tmp_path / "cg"), str(tmp_path / "proc_cgroup")) == 7 * GB


def test_cgroup_v2_without_a_limit_is_none(tmp_path):
    write(tmp_path / "proc_cgroup", "0::/\n")
    write(tmp_path / "cg/memory.max", "max\n")
    write(tmp_path / "cg/memory.current", f"{3 * GB}\n")
    assert _resources.cgroup_memory(str(tmp_path / "cg"), str(tmp_path / "proc_cgroup")) is None


def test_cgroup_v1_limit_less_usage_and_the_kernel_no_limit(tmp_path):
    write(tmp_path / "proc_cgroup", "4:memory:/process_api/ab\n0::/\n")
    base = tmp_path / "cg/memory/process_api/ab"
    write(base / "memory.limit_in_bytes", f"{6 * GB}\n")
    write(base / "memory.usage_in_bytes", f"{1 * GB}\n")
    membership = str(tmp_path / "proc_cgroup")
    assert _resources.cgroup_memory(str(tmp_path / "cg"), membership) == 5 * GB
    write(base / "memory.limit_in_bytes", "9223372036854771712\n")  # v1's "no limit"
    assert _resources.cgroup_memory(str(tmp_path / "cg"), membership) is None


def test_usage_over_the_limit_leaves_nothing(tmp_path):
    write(tmp_path / "proc_cgroup", "0::/\n")
    write(tmp_path / "cg/memory.max", f"{2 * GB}\n")
    write(tmp_path / "cg/memory.current", f"{3 * GB}\n")
    assert _resources.cgroup_memory(str(tmp_path / "cg"), str(tmp_path / "proc_cgroup")) == 0


def test_an_address_space_limit_bounds_the_memory_a_solve_is_judged_against():
    """Under ``RLIMIT_AS`` of 12 GB the rule's memory is at most 12 GB less what the
    process has mapped, whatever the machine has."""
    code = textwrap.dedent(f"""
        import resource
        resource.setrlimit(resource.RLIMIT_AS, ({12 * GB}, {12 * GB}))
        from gearjax._studies import resources as h
        left = h.address_space_memory()
        print(left, h.host_memory())
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    left, host = map(int, out.stdout.split())
    assert 0 < left < 12 * GB and host <= left
