"""Result objects print short and serialise to JSON (mdsr_opt.core.results conventions)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mdsr_opt import Mesh
from mdsr_opt.core.results import format_value, to_jsonable


def test_helpers_summarise_arrays_and_make_json():
    assert format_value(np.zeros((4000, 2))) == "array((4000, 2), float64)"
    assert format_value(np.array([1.0, 2.0])) == "[1, 2]" == format_value([1.0, 2.0])
    assert format_value(np.full(7, 0.25)) == "[" + ", ".join(["0.25"] * 7) + "]"  # 7 muscles: values too
    assert format_value(np.zeros(54)) == "array((54,), float64)"
    assert format_value(list(range(50))) == "<50 items>"
    assert format_value(0.123456789) == "0.1235"
    d = to_jsonable({"a": np.arange(3, dtype=np.int64), "b": (np.float32(1.5), math.inf), "c": np.bool_(True)})
    assert d == {"a": [0, 1, 2], "b": [1.5, None], "c": True}
    assert json.loads(json.dumps(d)) == d


@pytest.fixture(scope="module")
def plate():
    return Mesh.rectangle(2.0, 1.0, 8, 4)


def test_routing_result_repr_and_dict(plate):
    from mdsr_opt.synthesis.routing import route_muscles

    target = plate.points * [0.8, 1.0]
    res = route_muscles(plate, target)
    text = repr(res)
    assert len(text) < 300 and text.startswith(f"RoutingResult({len(res)} muscle(s)") and "n_units=" in text
    d = json.loads(json.dumps(res.to_dict()))
    assert [m["nodes"] for m in d["muscles"]] == [list(m.nodes) for m in res]
    assert d["stats"][0]["contraction"] == pytest.approx(res.stats[0].contraction)
    assert d["params"]["K_a"] == res.params["K_a"]


def test_study_result_repr_and_dict():
    from mdsr_opt.studies.study import run_study

    res = run_study("quick", resolutions=[30], methods=["ipopt"], problems=["strip-stretch"], progress=False,
                    figures=False)
    text = repr(res)
    assert text.startswith("StudyResult(study='quick', runs=2, success=2") and len(text) < 200
    d = json.loads(json.dumps(res.to_dict()))  # strict JSON: NaN became null
    assert d["study"]["name"] == "quick" and len(d["rows"]) == 2 and d["rows"][0]["method"] == "ipopt"


def test_contour_comparison_and_photo_repr_and_dict(plate):
    from mdsr_opt.photos.compare import compare_contours, simulated_outline
    from mdsr_opt.photos.contours import contour_from_image
    from mdsr_opt.photos.camera import render_photo

    photo = render_photo(plate, plate.points, image_size=(300, 300), seed=1)
    assert repr(photo) == "SyntheticPhoto(300x300 px, seed=1, SYNTHETIC)"
    assert json.loads(json.dumps(photo.to_dict()))["synthetic"] is True
    comp = compare_contours(simulated_outline(plate, plate.points), contour_from_image(photo.image))
    text = repr(comp)
    assert text.startswith("ContourComparison(mean_px=") and "array" not in text and len(text) < 250
    d = json.loads(json.dumps(comp.to_dict()))
    assert d["mean_px"] == pytest.approx(comp.mean_px) and len(d["distances_px"]) == comp.n_nodes
    assert np.allclose(d["transform"], comp.transform)
