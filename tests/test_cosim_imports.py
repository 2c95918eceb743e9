"""Issue 27: the master and its settings do not import each other.

``fmugen/cosim/settings.py`` resolved the run settings with ``check_choices`` imported from the master inside
its functions, and the master imported ``resolve`` from the settings inside ``run()``: a circle, hidden by
the imports being late.  ``check_choices`` now lives with the settings, which import nothing of the master.

The graph is tests/test_import_graph.py's (every import, also those inside functions; that file fails on any
circle in the package); here the two modules' edges are checked by name, and a fresh interpreter imports the
settings alone and finds the master's public names still there.
"""
import subprocess
import sys

from test_import_graph import import_graph


def test_master_and_settings_import_in_one_direction():
    graph = import_graph()
    assert "fmugen.cosim.check_choices" not in graph  # names resolved to their modules
    assert "fmugen.cosim.master" in graph["fmugen.cosim.report"]  # the walk sees ordinary imports ...
    assert "fmugen.cosim.settings" in graph["fmugen.cosim.master"]
    assert "fmugen.cosim.master" not in graph["fmugen.cosim.settings"]


def test_a_fresh_interpreter_imports_the_settings_first():
    code = ("import fmugen.cosim.settings as s, fmugen.cosim.master as m; "
            "assert m.check_choices is s.check_choices and m.run and m.SCHEMES and m.EXTRAPOLATIONS; "
            "print(s.check_choices('gs', 'held'))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "('gauss-seidel', 'hold')"
