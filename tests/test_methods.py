"""Method registry, parameters, progress/cancellation, and the baselines on real shapes."""

from dataclasses import dataclass

import numpy as np
import pytest

from corrlib.errors import Cancelled, InputError, ParameterError
from corrlib.evaluation import geodesic_errors
from corrlib.methods import all_methods, get_method, make_params, methods_for, param, solve
from corrlib.methods.base import validate_params
from corrlib.progress import CancelToken, Progress, run
from corrlib.shapes import Contour2D


@dataclass(frozen=True, kw_only=True)
class P:
    k: int = param(5, label="k", help="count", low=1, high=10)
    w: float = param(0.5, label="w", help="weight", low=0.0)
    mode: str = param("a", label="mode", help="mode", choices=("a", "b"))
    flag: bool = param(False, label="flag", help="flag")


def test_params_validation_and_conversion():
    p = make_params(P, k="7", w="0.25", mode="b", flag="yes")
    assert (p.k, p.w, p.mode, p.flag) == (7, 0.25, "b", True)
    for bad, match in [({"k": 11}, "above its maximum"), ({"k": 0}, "below its minimum"),
                       ({"k": 2.5}, "integer"), ({"mode": "c"}, "not one of"), ({"w": float("nan")}, "finite"),
                       ({"zzz": 1}, "unknown parameter"), ({"k": "x"}, "cannot interpret"),
                       ({"flag": "maybe"}, "cannot interpret")]:
        with pytest.raises(ParameterError, match=match):
            make_params(P, **bad)
    with pytest.raises(ParameterError, match="must be a number"):
        validate_params(P(k="3"))


def test_registry_lookup(wolf_pair):
    names = [m.name for m in all_methods()]
    assert "fmap-zoomout" in names and "descriptor-nn" in names
    assert methods_for(*wolf_pair)[0].rank >= methods_for(*wolf_pair)[-1].rank
    with pytest.raises(ParameterError, match="unknown method"):
        get_method("nothing")
    t = np.linspace(0, 2 * np.pi, 30, endpoint=False)
    contour = Contour2D(np.column_stack([np.cos(t), np.sin(t)]))
    with pytest.raises(InputError, match="takes mesh"):
        solve("descriptor-nn", contour, wolf_pair[1])


def test_run_and_cancel():
    def gen(token):
        for i in range(5):
            token.raise_if_cancelled()
            yield Progress("step", i / 5)
        return 42

    seen = []
    token = CancelToken()
    assert run(gen(token), seen.append, token) == 42 and len(seen) == 5
    token = CancelToken()

    def cancel_at_two(report):
        if report.fraction >= 0.4:
            token.cancel()

    with pytest.raises(Cancelled):
        run(gen(token), cancel_at_two, token)


@pytest.mark.parametrize("method, threshold", [("descriptor-nn", 0.6), ("fmap-zoomout", 0.95)])
def test_baselines_on_wolf(wolf_pair, method, threshold):
    wolf0, wolf1 = wolf_pair
    reports = []
    result = solve(method, wolf0, wolf1, callback=reports.append)
    assert reports and reports[-1].fraction == 1.0
    assert result.map_xy.shape == (wolf0.n_vertices,) and result.map_yx.shape == (wolf1.n_vertices,)
    ident = np.arange(wolf0.n_vertices)
    err = geodesic_errors(result.map_xy, wolf1, ident, ident).summary()
    # descriptor-nn: intrinsic descriptors confuse left and right, so only a majority is near-exact; the
    # functional map's orientation term keeps left on left (measured: 99.4 % within 0.025, mean 0.002)
    assert err["within_0.025"] > threshold, err
    assert result.timings["total"] > 0 and result.params


def test_baseline_is_invariant_to_vertex_permutation(wolf_pair):
    from corrlib.shapes import TriMesh

    wolf0, wolf1 = wolf_pair
    perm = np.random.default_rng(3).permutation(wolf1.n_vertices)
    inv = np.argsort(perm)
    shuffled = TriMesh(wolf1.vertices[perm], inv[wolf1.faces])
    a = solve("descriptor-nn", wolf0, wolf1).map_xy
    b = solve("descriptor-nn", wolf0, shuffled).map_xy
    assert np.mean(perm[b] == a) > 0.99


def test_cancel_a_method(wolf_pair):
    token = CancelToken()
    token.cancel()
    with pytest.raises(Cancelled):
        solve("fmap-zoomout", *wolf_pair, token=token)


def test_result_save(tmp_path, wolf_pair):
    from corrlib.io import load_result

    result = solve("descriptor-nn", *wolf_pair)
    result.save(tmp_path / "out")
    arrays, meta = load_result(tmp_path / "out")
    assert np.array_equal(arrays["map_xy"], result.map_xy)
    assert meta["method"] == "descriptor-nn" and meta["params"]["descriptor"] == "wks"


def test_warm_up_runs_every_kernel():
    from corrlib.warmup import warm_up

    warm_up()  # tiny problems through the auction, layered Dijkstra, L1 costs and SHOT


def test_every_solver_follows_the_solver_contract():
    """``solve_<name>(source, target, params, token)``; refining solvers add a keyword-only ``initial=None``."""
    import inspect

    from corrlib.methods import all_methods

    for spec in all_methods():
        assert spec.solve.__name__ == "solve_" + spec.name.replace("-", "_"), spec.name
        sig = inspect.signature(spec.solve)
        positional = [p for p in sig.parameters.values() if p.kind is p.POSITIONAL_OR_KEYWORD]
        assert [p.name for p in positional] == ["source", "target", "params", "token"], spec.name
        assert all(p.default is p.empty for p in positional), spec.name
        keyword = {p.name: p for p in sig.parameters.values() if p.kind is p.KEYWORD_ONLY}
        if spec.refines:
            assert set(keyword) == {"initial"} and keyword["initial"].default is None, spec.name
        else:
            assert not keyword, spec.name


def test_registering_a_name_twice_is_a_parameter_error():
    from dataclasses import replace

    from corrlib.errors import ParameterError
    from corrlib.methods import get_method
    from corrlib.methods.registry import register

    spec = get_method("descriptor-nn")
    assert register(spec) is spec  # the same spec again is harmless
    with pytest.raises(ParameterError, match="already registered"):
        register(replace(spec, label="another"))


def test_typed_result_parts_survive_save_and_load(tmp_path):
    from corrlib.methods.base import ContourPath, MatchResult, SearchCertificate

    rng = np.random.default_rng(3)
    path = ContourPath(rng.random((7, 2)), np.array([0, 4, 4, 2]), np.array([0, 2, 4, 6]), np.array([0, 2, 4, 7]),
                       target_points=rng.random((5, 2)), product_functions={"cost": rng.random((7, 5))})
    result = MatchResult("contour2d", np.arange(7) % 5, None, 1.5, {"total": 0.1}, {"n_source": 7},
                         energy_meaning="path energy", energy_trace=np.array([3.0, 2.0, 1.5]), path=path,
                         search=SearchCertificate(1.4, 1.5, 9, 12, 0.01),
                         extras={"band_size": 0.25, "path_map_xy": np.arange(7)})
    result.save(tmp_path / "r")
    loaded = MatchResult.load(tmp_path / "r.json")
    assert loaded.method == "contour2d" and loaded.energy == 1.5 and loaded.energy_meaning == "path energy"
    assert np.array_equal(loaded.map_xy, result.map_xy) and loaded.map_yx is None
    assert np.array_equal(loaded.energy_trace, result.energy_trace)
    for name in ("contour_points", "vertices", "contour_index", "layers", "target_points"):
        assert np.array_equal(getattr(loaded.path, name), getattr(path, name)), name
    assert np.array_equal(loaded.path.product_functions["cost"], path.product_functions["cost"])
    assert loaded.search == result.search and not loaded.search.optimal
    assert loaded.search.gap == pytest.approx(0.1)
    assert loaded.extras["band_size"] == 0.25 and np.array_equal(loaded.extras["path_map_xy"], np.arange(7))
    assert loaded.deformation is None
    assert loaded == result and loaded.path == path  # the save's promise: an equal result


def test_results_compare_by_value():
    """``==`` on results and contour paths compares every field by value (arrays entry by entry, NaN equal to
    NaN, a tuple equal to the list JSON gives back); a dataclass's generated ``==`` raised on the arrays."""
    from corrlib.methods.base import ContourPath, MatchResult, same_values

    def made(**changes):
        fields = dict(method="m", map_xy=np.array([2, 0, 1]), energy=float("nan"), timings={"total": 0.5},
                      energy_trace=np.array([1.0, np.nan]), extras={"sizes": (3, 4), "rows": np.arange(3)},
                      path=ContourPath(np.zeros((3, 2)), np.array([0, 1]), np.array([0, 1]), np.array([0, 1])))
        fields.update(changes)
        return MatchResult(**fields)

    assert made() == made(extras={"sizes": [3, 4], "rows": np.arange(3)})
    assert made() != made(map_xy=np.array([2, 1, 0]))
    assert made() != made(map_xy=np.array([2, 0, 1, 0]))
    assert made() != made(extras={"sizes": (3, 4)})
    assert made() != made(path=None)
    assert made() != made(energy_trace=np.array([1.0, 2.0]))
    assert made().__eq__("a result") is NotImplemented
    assert same_values({"a": np.ones(2)}, {"a": np.ones(2)}) and not same_values(np.ones(2), np.ones((2, 1)))
    with pytest.raises(TypeError, match="unhashable"):
        hash(made().path)


def test_scaled_progress_maps_fractions_and_returns_the_result():
    from corrlib.progress import scaled_progress

    def solver():
        yield Progress("a", 0.0, "start")
        yield Progress("b", -1.0, "")
        yield Progress("c", 1.0, "done")
        return 42

    reports = []
    assert run(scaled_progress(solver(), 0.5, 1.0, "second"), callback=reports.append) == 42
    assert [r.fraction for r in reports] == [0.5, -1.0, 1.0]  # an unknown fraction stays unknown
    assert [r.message for r in reports] == ["second: start", "second", "second: done"]
