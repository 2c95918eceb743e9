"""The work-precision plot's fixed look: every scheme x extrapolation the master offers has a colour, a marker
and a line style of its own (the issue-27 plot had jacobi/linear and the monolithic FMU both orange, jacobi/hold
and newton/cubic both blue: matplotlib's colour cycle, in order of appearance), the same in every plot."""
from fmugen.cosim.interpolants import EXTRAPOLATIONS
from fmugen.cosim.report import scheme_style
from fmugen.cosim.schemes import SCHEMES


def _look(st):
    return st["color"], st["marker"], st["linestyle"]


def test_every_scheme_has_a_look_of_its_own_and_keeps_it():
    labels = [f"{s}/{e}" for s in SCHEMES for e in EXTRAPOLATIONS] + ["monolithic FMU"]
    looks = [_look(scheme_style(lab)) for lab in labels]
    assert len(set(looks)) == len(labels)
    assert len({c for c, _, _ in looks}) == len(labels)  # the colour alone tells them apart
    # the same whatever else the plot holds, and in whatever order
    assert _look(scheme_style("newton/cubic")) == looks[labels.index("newton/cubic")]
    others = []
    assert _look(scheme_style("monolithic FMU", others)) == looks[-1]
    assert _look(scheme_style("some other row", others)) not in looks
    # an internal-solver variant keeps its scheme's colour and marker, hollow
    v = scheme_style("newton/cubic rodas3 1e-10")
    assert _look(v) == looks[labels.index("newton/cubic")] and v["markerfacecolor"] == "none"
