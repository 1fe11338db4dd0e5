"""The studies' task engine (:mod:`cosim.studies.engine`): results in the tasks' order on
any scheduler, the refusals."""
import math

import pytest

from cosim.studies.engine import check_scheduler, run_tasks


def test_results_come_in_the_tasks_order_on_one_or_two_workers():
    tasks = [9.0, 4.0, 1.0, 16.0]
    done = []
    assert run_tasks(math.sqrt, tasks, jobs=1, on_done=lambda: done.append(1)) == \
        [3.0, 2.0, 1.0, 4.0]
    assert len(done) == 4
    assert run_tasks(math.sqrt, tasks, jobs=2) == [3.0, 2.0, 1.0, 4.0]
    assert run_tasks(math.sqrt, [], jobs=1) == []


def test_bad_scheduler_and_jobs_are_refused():
    for bad in ("cluster", "http://x:1", "", None):
        with pytest.raises(ValueError, match="scheduler"):
            check_scheduler(bad)
    assert check_scheduler("tcp://10.0.0.1:8786") == "tcp://10.0.0.1:8786"
    with pytest.raises(ValueError, match="jobs"):
        run_tasks(math.sqrt, [1.0], jobs=0)


@pytest.mark.slow
def test_a_local_dask_cluster_gives_the_same_results():
    """In a subprocess (a Dask cluster leaves threads behind)."""
    pytest.importorskip("distributed")
    import subprocess
    import sys
    p = subprocess.run([sys.executable, "-c",
                        "import math; from cosim.studies.engine import run_tasks; "
                        "print(run_tasks(math.sqrt, [9.0, 4.0, 1.0, 16.0], jobs=2, "
                        "scheduler='dask'))"], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    assert p.stdout.strip().splitlines()[-1] == "[3.0, 2.0, 1.0, 4.0]"
