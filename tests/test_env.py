"""Process set-up done by ``import invface`` (invface/_env.py)."""
import json
import os
import subprocess
import sys

PROBE = ("import numpy, scipy.linalg, invface, json, threadpoolctl; print(json.dumps(["
         "i['num_threads'] for i in threadpoolctl.threadpool_info() if i['internal_api'] == 'openblas']))")


def _openblas_threads(**env):
    e = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    e.update(env)
    out = subprocess.run([sys.executable, "-c", PROBE], env=e, capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_openblas_runs_on_one_thread_unless_the_user_chose():
    """numpy imported first (its OpenBLAS loaded before invface): limited to one thread all
    the same; scipy's, loaded after, too. A user's OPENBLAS_NUM_THREADS is left alone."""
    assert _openblas_threads() and set(_openblas_threads()) == {1}
    assert set(_openblas_threads(OPENBLAS_NUM_THREADS="2")) == {2}
