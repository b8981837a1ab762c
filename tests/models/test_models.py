"""The networks: shapes, gradients, ROI cropping, edge decoding, checkpoints, and overfitting."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from affine import Affine

from csboundary.errors import InputError
from csboundary.models.afanet import AfANet, AfANetConfig, crop_rois, edges_from_adjacency
from csboundary.models.checkpoint import load_checkpoint, save_checkpoint
from csboundary.models.device import resolve_device
from csboundary.models.fpn import FPN, FPNConfig

SMALL_AFANET = AfANetConfig(global_size=64, roi=32, encoder_widths=(8, 16, 32), dim=64, layers=2)


def test_fpn_keeps_any_input_size():
    model = FPN(FPNConfig(widths=(8, 16, 16, 16), blocks=(1, 1, 1, 1), pyramid=8, stem=8)).eval()
    with torch.no_grad():
        out = model(torch.rand(2, 4, 100, 130))
    assert out.shape == (2, 2, 100, 130)


def test_afanet_embedding_is_2050_and_adjacency_is_m_by_m():
    model = AfANet(AfANetConfig()).eval()
    tensor = torch.rand(6, 200, 200)
    with torch.no_grad():
        assert model.embed(tensor, torch.rand(3, 2) * 200).shape == (3, 2050)
        for m in (0, 1, 2, 57):
            logits = model(tensor, torch.rand(m, 2) * 200)
            assert logits.shape == (m, m)
            p = model.adjacency(tensor, torch.rand(m, 2) * 200)
            assert torch.allclose(p, p.T) and (p.diagonal() == 0).all()


def test_ablation_switches_remove_a_feature():
    assert AfANetConfig(use_global=False).embedding == 1026
    assert AfANetConfig(use_local=False).embedding == 1026
    model = AfANet(
        AfANetConfig(use_global=False, **{k: v for k, v in SMALL_AFANET.to_dict().items() if k != "use_global"})
    )
    assert model.global_encoder is None and model(torch.rand(6, 64, 64), torch.rand(4, 2) * 64).shape == (4, 4)
    with pytest.raises(ValueError):
        AfANet(AfANetConfig(use_global=False, use_local=False))


def test_gradients_reach_both_encoder_branches():
    model = AfANet(SMALL_AFANET)
    logits = model(torch.rand(6, 96, 96), torch.rand(5, 2) * 96)
    logits.sum().backward()
    for branch in (model.global_encoder, model.local_encoder):
        grads = [p.grad for p in branch.parameters()]
        assert all(g is not None for g in grads) and sum(float(g.abs().sum()) for g in grads) > 0


def test_roi_crops_are_centred_on_pixel_centres_and_zero_outside():
    tensor = torch.arange(100.0).reshape(1, 10, 10)  # value = 10 * row + col
    rois = crop_rois(tensor, torch.tensor([[5.5, 4.5], [0.5, 0.5]]), 3)
    assert rois.shape == (2, 1, 3, 3)
    # Vertex at the centre of pixel [4, 5]: the window covers rows 3..5 and cols 4..6.
    expected = torch.tensor([[10.0 * r + c for c in range(4, 7)] for r in range(3, 6)])
    assert torch.allclose(rois[0, 0], expected, atol=1e-4)
    # Vertex at the centre of pixel [0, 0]: rows/cols -1..1, the first of each outside (zero).
    corner = torch.tensor([[0, 0, 0], [0, 0, 1], [0, 10, 11.0]])
    assert torch.allclose(rois[1, 0], corner, atol=1e-4)
    even = crop_rois(tensor, torch.tensor([[5.5, 4.5]]), 2)  # even windows straddle the vertex
    assert torch.allclose(even[0, 0], torch.tensor([[39.5, 40.5], [49.5, 50.5]]), atol=1e-4)


def test_edges_respect_threshold_degree_and_fixed_edges():
    p = torch.tensor([[0, 0.9, 0.8, 0.7], [0.9, 0, 0.6, 0.2], [0.8, 0.6, 0, 0.95], [0.7, 0.2, 0.95, 0]])
    assert edges_from_adjacency(p, 0.5, None) == [(0, 1), (0, 2), (0, 3), (1, 2), (2, 3)]
    # Greedy by probability with degree <= 2: (2,3) .95, (0,1) .9, (0,2) .8; (0,3) and (1,2) would exceed.
    assert edges_from_adjacency(p, 0.5, 2) == [(0, 1), (0, 2), (2, 3)]
    assert edges_from_adjacency(p, 0.5, 2, fixed=[(3, 1)]) == [(0, 1), (0, 2), (1, 3), (2, 3)]


def test_device_choice():
    assert resolve_device("cpu").type == "cpu"
    assert resolve_device("auto").type in ("cpu", "cuda")
    with pytest.raises(InputError, match="--device: must be auto"):
        resolve_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(InputError, match="no CUDA"):
            resolve_device("cuda")


def test_checkpoints_say_what_is_wrong(tmp_path):
    path = save_checkpoint(tmp_path / "f.pt", "fpn", fpn={}, fpn_config={})
    assert load_checkpoint(path, ("fpn",))["kind"] == "fpn"
    with pytest.raises(InputError, match="f.pt: holds a 'fpn' model; expected afanet"):
        load_checkpoint(path, ("afanet",))
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not torch")
    with pytest.raises(InputError, match="junk.pt: not a readable weights file"):
        load_checkpoint(junk, ("fpn",))
    with pytest.raises(InputError, match="weights file not found"):
        load_checkpoint(tmp_path / "none.pt", ("fpn",))


@pytest.fixture(scope="module")
def one_patch():
    """A 320 px window of a small synthetic city: image, label maps, ground-truth vertices, adjacency."""
    from csboundary.data.synth.city import plan_city
    from csboundary.data.synth.config import SynthConfig
    from csboundary.data.windows import PixelWindow
    from csboundary.labels.boundaries import boundaries_from_world
    from csboundary.labels.config import LabelConfig
    from csboundary.labels.keypoints import compute_keypoints
    from csboundary.labels.patch_graph import window_graph
    from csboundary.labels.rasterize import keypoint_heat, segmentation_label
    from csboundary.labels.select import boundary_bounds

    city = plan_city(SynthConfig(tile_size=700, gsd=0.3), "train", 5, (1, 1))
    transform = Affine(0.3, 0, 0, 0, -0.3, city.size_m[1])
    boundaries = boundaries_from_world([line for line, _ in city.scene.network.boundaries], transform)
    config = LabelConfig(aux_spacing_px=100)
    kps, bounds = compute_keypoints(boundaries, config), boundary_bounds(boundaries)
    window = PixelWindow(190, 190, 320, 320)
    image = city.render(0, 0)[:, 190:510, 190:510].astype(np.float32) / 255
    heat = keypoint_heat(kps, bounds, window)
    seg = segmentation_label(boundaries, bounds, window).astype(np.float32)
    graph, _ = window_graph(kps, bounds, window)
    label = np.zeros((graph.n_vertices, graph.n_vertices), np.float32)
    label[graph.edges[:, 0], graph.edges[:, 1]] = label[graph.edges[:, 1], graph.edges[:, 0]] = 1
    return image, np.stack([heat, seg]), graph, label


def test_afanet_overfits_one_patch_and_recovers_its_graph(one_patch):
    from csboundary.models.training.afanet import adjacency_loss

    torch.manual_seed(0)
    image, maps, graph, label = one_patch
    assert 6 <= graph.n_vertices <= 80 and graph.n_edges >= 4
    tensor = torch.from_numpy(np.concatenate([image, maps]))
    vertices = torch.from_numpy(graph.vertices.astype(np.float32))
    target = torch.from_numpy(label)
    model = AfANet(SMALL_AFANET)
    optimizer = torch.optim.Adam(model.parameters(), lr=2e-3)
    losses = []
    for _ in range(100):
        loss = adjacency_loss(model(tensor, vertices), target, 30.0)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    assert losses[-1] < losses[0] / 10
    model.eval()
    edges = edges_from_adjacency(model.adjacency(tensor, vertices), 0.5, 2)
    assert edges == sorted(tuple(sorted(map(int, e))) for e in graph.edges)


def test_fpn_overfits_one_patch(one_patch):
    from csboundary.models.training.config import TrainConfig
    from csboundary.models.training.fpn import fpn_loss

    torch.manual_seed(0)
    image, maps, _, _ = one_patch
    x = torch.from_numpy(image[None, :, :128, :128].copy())
    y = torch.from_numpy(maps[None, :, :128, :128].copy())
    valid = torch.ones(1, 128, 128, dtype=torch.bool)
    model = FPN(FPNConfig(widths=(16, 24, 32, 32), blocks=(1, 1, 1, 1), pyramid=24, stem=16))
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    config = TrainConfig()
    losses = []
    for _ in range(200):
        loss = fpn_loss(model(x), y, valid, config)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    # The keypoint target is soft heat, so BCE cannot reach 0: its floor is the loss of a perfect
    # prediction (logits = logit(target)). The excess over that floor must fall tenfold.
    floor = fpn_loss(torch.logit(y.clamp(1e-6, 1 - 1e-6)), y, valid, config).item()
    assert losses[-1] - floor < (losses[0] - floor) / 10
