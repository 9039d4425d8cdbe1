"""Model zoo (thesis 2.3.1, Tables 2.1 and 2.3): names, parameter counts, shapes, inputs."""

import json

import numpy as np
import pytest
import torch

from perception.inputs import NORMALISATION, input_channels, line_edge_maps, network_input
from perception.zoo import ZOO, build_model, grid_label, parameter_count, parse_name

# Table 2.3 as printed: (model string, parameter count, grid label whose count it is).
TABLE_2_3 = [
    ("k64-k64-p2-k128-k128-d1-d2-d4-d8-d16-d1-k2", 1_147_970, "f1c5"),
    ("k64-k64-p2-k128-k128-d1-d2-d4-d1-k2", 852_802, "f1c3"),
    ("k64-k64-p2-k128-k128-d1-d2-d4-d8-d1-k2", 1_000_386, "f1c4"),
    ("k32-k32-k32-d1-d2-d4-d8-d16-d1-k2", 84_706, "f3c5"),
    ("k64-k64-p2-k128-k128-d1-d2-d1-k2", 705_218, "f1c2"),
    ("k32-k32-k64-k64-d1-d2-d4-d8-d16-d1-k2", 288_290, "f2c5"),
    ("k32-k32-d1-d2-d4-d8-d16-d1-k2", 66_210, "f6c5"),
    ("k32-k32-k32-k32-k32-d1-d2-d4-d8-d1-k2", 93_954, "f5c4"),
    ("k32-k32-k64-k64-k64-k64-d1-d2-d4-d8-d16-d1-k2", 362_146, "f4c5"),
    ("k32-k32-k32-d1-d2-d4-d8-d1-k2", 75_458, "f3c4"),
    ("k32-k32-k64-k64-d1-d2-d4-d1-k2", 214_434, "f2c3"),
    ("k32-k32-k32-k32-k32-d1-d2-d4-d1-k2", 84_706, "f5c3"),
    ("k32-k32-k64-k64-k64-d1-d2-d1-k2", 251_362, "f4c2"),
    ("k32-k32-k64-k64-k64-k64-d1-d2-d4-d8-d1-k2", 325_218, "f4c4"),
]


@pytest.mark.parametrize(("printed", "count", "label"), TABLE_2_3)
def test_grid_models_reproduce_every_count_of_table_2_3(printed, count, label):
    assert parameter_count(build_model(label)) == count


@pytest.mark.parametrize(("printed", "count", "label"), TABLE_2_3)
def test_table_2_3_strings_are_literal_only_where_self_consistent(printed, count, label):
    """Six strings of Table 2.3 (f3, f5 and one f4 row) are one layer short of their counts:
    the grid keeps the count (and 2.3.1's prose), parsing the string literally does not."""
    literal = parameter_count(build_model(printed))
    if ZOO[label] == printed:
        assert literal == count
    else:
        assert literal != count
        assert len(parse_name(ZOO[label])) == len(parse_name(printed)) + 1


def test_default_and_named_counts():
    assert parameter_count(build_model("k32-k32-d1-d2-d4-d8-d16-d1-k2")) == 66_210
    assert parameter_count(build_model("k64-k64-p2-k128-k128-d1-d2-d4-d1-k2")) == 852_802
    assert parameter_count(build_model("k64-k64-p2-k128-k128-d1-d2-d4-d8-d16-d1-k2")) == 1_147_970
    # RGBLE adds 2 input channels x 9 taps x 32 filters to the first layer.
    assert parameter_count(build_model("f6c5", in_channels=5)) == 66_210 + 2 * 9 * 32


def test_zoo_has_the_30_grid_models():
    assert len(ZOO) == 30 and len(set(ZOO.values())) == 30
    assert {k[:2] for k in ZOO} == {f"f{i}" for i in range(1, 7)}
    assert {k[2:] for k in ZOO} == {f"c{i}" for i in range(1, 6)}
    assert grid_label("k32-k32-d1-d2-d4-d8-d16-d1-k2") == "f6c5"
    assert grid_label("k32-k2") is None


@pytest.mark.parametrize("name", ["f6c5", "f1c3", "k64-p2-k32-p2-k2", "f3c1", "k8-p2-d2-k2-s"])
@pytest.mark.parametrize(("h", "w"), [(37, 53), (16, 16), (9, 31)])
def test_logits_have_input_resolution(name, h, w):
    model = build_model(name, in_channels=5).eval()
    with torch.no_grad():
        out = model(torch.randn(2, 5, h, w))
    assert out.shape == (2, 2, h, w)
    assert torch.isfinite(out).all()


def test_dilated_layers_keep_channels_and_dilate():
    convs = [m for m in build_model("f6c5").modules() if isinstance(m, torch.nn.Conv2d)]
    assert [c.dilation[0] for c in convs] == [1, 1, 1, 2, 4, 8, 16, 1, 1]
    assert [c.out_channels for c in convs] == [32] * 8 + [2]
    assert all(c.kernel_size == (3, 3) for c in convs)


def test_skip_adds_full_resolution_logits_that_start_at_zero():
    pooled, skipped = build_model("k8-k8-p2-d1-k2"), build_model("k8-k8-p2-d1-k2-s")
    # 8 full-resolution channels x 9 taps x 2 logits + 2 biases
    assert parameter_count(skipped) == parameter_count(pooled) + 8 * 9 * 2 + 2
    skipped.load_state_dict(pooled.state_dict(), strict=False)
    x = torch.randn(1, 3, 21, 30)
    with torch.no_grad():
        assert torch.equal(pooled(x), skipped(x))  # zero-initialised: the same model at first
        skipped.skip.bias.copy_(torch.tensor([0.0, 1.0]))
        assert torch.allclose(skipped(x) - pooled(x), torch.tensor([0.0, 1.0])[:, None, None])
    assert parameter_count(build_model("k32-k32-p2-d1-d2-d4-d8-d16-d1-k2-s")) == 66_210 + 578


@pytest.mark.parametrize(
    "bad", ["k32-d2", "k32-x3-k2", "d2-k2", "k0-k2", "", "k32-k2-s", "k32-p2-s-k2", "k8-p2-k2-s-s"]
)
def test_malformed_names_are_rejected(bad):
    with pytest.raises(ValueError):
        build_model(bad)


def test_rgb_input_normalisation():
    image = np.zeros((4, 6, 3), np.uint8)
    image[..., 0] = 255
    x = network_input(image, "rgb")
    assert x.shape == (3, 4, 6) and x.dtype == np.float32
    mean, std = NORMALISATION["mean"][0], NORMALISATION["std"][0]
    assert np.allclose(x[0], (1 - mean) / std) and np.allclose(x[1], (0 - mean) / std)


def test_rgble_has_line_and_edge_channels_on_a_drawn_line():
    image = np.full((64, 96, 3), 200, np.uint8)
    image[30:32, 10:86] = 20  # a dark horizontal bar: a line segment with two edges
    x = network_input(image, "rgble")
    assert x.shape == (input_channels("rgble"), 64, 96)
    assert set(np.unique(x[3:])) <= {-1.0, 1.0}
    lines, edges = line_edge_maps(image)
    assert lines[28:34, 20:76].any(axis=0).mean() > 0.9  # LSD found the bar along its length
    assert edges[28:34, 20:76].any(axis=0).all()
    assert not lines[:20].any() and not edges[:20].any()  # nothing in the flat part


def test_input_rejects_wrong_images():
    with pytest.raises(ValueError):
        network_input(np.zeros((4, 4, 3), np.float32))
    with pytest.raises(ValueError):
        network_input(np.zeros((4, 4, 3), np.uint8), "rgbd")  # type: ignore[arg-type]


def test_zoo_command_lists_counts():
    from typer.testing import CliRunner

    from companion.cli import app

    result = CliRunner().invoke(app, ["zoo", "f6c5", "f1c3", "--json"])
    assert result.exit_code == 0, result.output
    rows = json.loads(result.output)
    assert [(r["label"], r["parameters"]) for r in rows] == [("f6c5", 66_210), ("f1c3", 852_802)]
    assert rows[1]["model"] == "k64-k64-p2-k128-k128-d1-d2-d4-d1-k2"
    bad = CliRunner().invoke(app, ["zoo", "k32-d2"])
    assert bad.exit_code != 0
