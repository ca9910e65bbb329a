r"""Joint R, G, B fits of the standard material models (glTF, principled, ...): one roughness (metallic, IOR, ...)
for the three colour channels of a material, a colour per channel.

A model with ``shared_across_channels`` is fitted through its *joint* record (``<name>:rgb``): parameters
``[shared..., colour(R)..., colour(G)..., colour(B)...]``, evaluated as the three channels' BRDFs stacked
``(3 n,)``, so that the multi-start Levenberg-Marquardt of :mod:`baselines._multistart` minimises the sum of the
three channels' equation (11) objectives

.. math:: \sum_{c \in \{R, G, B\}} \sum_i w_i \cos^2\theta_{u,i}\, (b_{c,i} - f(u_i, v_i; \tau_s, \tau_c))^2

over the shared ``tau_s`` and the per-channel ``tau_c`` at once (unchanged: the starts, stages, range-limit rounds
and the implicit derivative of the kept optimum, :mod:`baselines._implicit`).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from .common import BaselineModel

#: suffix of a joint record's registry name
SUFFIX = ":rgb"


def channel_index(model: BaselineModel) -> np.ndarray:
    """``(3, P)`` positions in the joint parameter vector of each channel's ``P`` parameters."""
    names = model.param_names
    shared = [names.index(n) for n in model.shared_across_channels]
    colour = [i for i in range(len(names)) if i not in shared]
    idx = np.zeros((3, len(names)), np.int32)
    for c in range(3):
        idx[c, shared] = np.arange(len(shared))
        idx[c, colour] = len(shared) + c * len(colour) + np.arange(len(colour))
    return idx


def per_channel(model: BaselineModel, joint_params):
    """``(..., Pj) -> (..., 3, P)``: each channel's parameters (raw or constrained) from a joint vector."""
    return joint_params[..., channel_index(model)]


def _joint_order(model: BaselineModel) -> list[int]:
    """The per-channel parameter of each joint position: shared first, then the colours of R, G, B."""
    idx = channel_index(model)
    order = [0] * (int(idx.max()) + 1)
    for c in range(3):
        for i, j in enumerate(idx[c]):
            order[j] = i
    return order


def _joint_values(model: BaselineModel, values) -> np.ndarray:
    """Per-channel ``(S, P)`` values (guesses) as joint vectors ``(S, Pj)``: the same value in each channel."""
    return np.asarray(values, float)[:, _joint_order(model)]


def joint_model(model: BaselineModel) -> BaselineModel:
    """The joint record of ``model`` (see the module docs): ``evaluate(p (Pj,), u, v) -> (3 n,)``."""
    order = _joint_order(model)
    names = model.param_names
    colour = [n for n in names if n not in model.shared_across_channels]
    jnames = tuple(model.shared_across_channels) + tuple(f"{n}[{c}]" for c in "RGB" for n in colour)

    def evaluate(p, u, v):
        if model.evaluate_rgb is not None:
            return model.evaluate_rgb(per_channel(model, p), u, v).reshape(-1)
        return jax.vmap(lambda q: model.evaluate(q, u, v))(per_channel(model, p)).reshape(-1)

    def sample(key, k):
        return jnp.asarray(model.sample(key, k))[:, jnp.asarray(order)]

    return dataclasses.replace(
        model, name=model.name + SUFFIX, param_names=jnames, transforms=tuple(model.transforms[i] for i in order),
        evaluate=evaluate, n_linear=0, columns=None, guesses=_joint_values(model, model.guesses), sample=sample,
        shared_across_channels=(), to_material=None, evaluate_rgb=None,
    )


def joint_lanes(values, wl, wc2):
    """Per-channel lanes ``(B, n)`` (``B = 3 M``, channels last) as material lanes ``(M, 3 n)``."""
    b, n = values.shape
    shape = (b // 3, 3 * n)
    return (values.reshape(shape), jnp.broadcast_to(wl, (b, n)).reshape(shape),
            jnp.broadcast_to(wc2, (b, n)).reshape(shape))
