"""The busy-machine warning: known answers for load, cores and threads."""

from latentrl.timing import busy_machine_warning


def test_warns_only_when_threads_cannot_each_get_a_core():
    assert busy_machine_warning(2, load=0.1, cpus=2) is None  # a quiet machine
    assert busy_machine_warning(2, load=1.2, cpus=2) is None  # the load of this process itself
    assert busy_machine_warning(1, load=5.0, cpus=2) is None  # one thread degrades gracefully
    assert busy_machine_warning(8, load=2.0, cpus=16) is None
    msg = busy_machine_warning(2, load=2.2, cpus=2)  # one other busy process
    assert msg is not None and "load 2.2 on 2 cores" in msg and "threads: 1" in msg


def test_uses_the_system_load_by_default():
    import os

    assert busy_machine_warning(1) is None
    if hasattr(os, "getloadavg"):  # Linux, macOS: 4096 threads never fit one core, whatever the load
        assert "4096 torch threads" in busy_machine_warning(4096, cpus=1)
