"""AfANet: attention for adjacency (paper IV-D).

Encoder: the 6-channel tensor (4 image bands, keypoint and segmentation probabilities) gives
a 1024-d global feature (the whole tensor, resized to ``global_size`` so the cost does not grow
with the patch) and, per vertex, a 1024-d local feature from the ``roi`` x ``roi`` window centred
on it (bilinear, zero outside the patch); with the vertex's normalised (x, y) that is a 2050-d
embedding. Either feature can be switched off for the paper's ablation (Table IV).

Decoder: the embedding (plus Fourier features of the coordinates, see ``decoder_input``) is
projected to ``dim``, then a stack of attention modules (queries and keys from vertex-centred
tokens, see ``centred``), each softmax(t * norm(Q) norm(K)^T) V with L2-normalised
queries and keys (paper eq. 1; ``t`` is a learnable temperature, since cosine similarities in
[-1, 1] alone give an almost flat softmax), with residuals and feed-forward layers; the final AfA
module returns norm(Q) norm(K)^T (paper eq. 2) as the M x M adjacency score. Training reads it
through a learnable affine map as BCE logits; at inference the probabilities are symmetrised.
Works for every M, including 0 and 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from csboundary.config import Config


@dataclass(frozen=True)
class AfANetConfig(Config):
    in_channels: int = 6
    feature: int = 1024  # global and local feature length (paper: 1024 each)
    roi: int = 64  # L, the local window side in pixels (paper: 64)
    global_size: int = 256  # the global branch sees the tensor resized to this side
    encoder_widths: tuple[int, ...] = (16, 32, 64, 128)  # stride-2 conv stages of each branch
    dim: int = 256  # decoder width
    position_frequencies: int = 8  # Fourier features of (x, y) at the decoder input; 0 = raw only
    layers: int = 3  # attention modules before the AfA module
    use_global: bool = True
    use_local: bool = True

    @property
    def embedding(self) -> int:
        return self.feature * (int(self.use_global) + int(self.use_local)) + 2


class ConvEncoder(nn.Module):
    """Stride-2 conv stages, global average pooling, and a linear map to ``feature`` values."""

    def __init__(self, cin: int, widths: tuple[int, ...], feature: int):
        super().__init__()
        layers = []
        for w in widths:
            layers += [nn.Conv2d(cin, w, 3, 2, 1, bias=False), nn.BatchNorm2d(w), nn.ReLU(inplace=True)]
            cin = w
        self.body = nn.Sequential(*layers)
        self.out = nn.Linear(cin, feature)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.out(self.body(x).mean(dim=(2, 3)))


def l2norm(x: torch.Tensor) -> torch.Tensor:
    return F.normalize(x, dim=-1, eps=1e-6)


def centred(h: torch.Tensor) -> torch.Tensor:
    """Subtract the mean over the vertices of a patch.

    Not in the paper: what all vertices of a patch share (the global feature, the look of the
    patch) would otherwise dominate every query and key, and the cosine similarity of any two
    vertices would be close to 1 whatever their relation. Centred, queries and keys carry only
    what tells vertices apart. (One vertex: its centred value is 0, and l2norm's eps keeps it
    finite.)
    """
    return h - h.mean(dim=-2, keepdim=True)


class AttentionModule(nn.Module):
    """x + softmax(t norm(Q) norm(K)^T) V, then x + FFN(x) (pre-norm)."""

    def __init__(self, dim: int):
        super().__init__()
        self.norm1, self.norm2 = nn.LayerNorm(dim), nn.LayerNorm(dim)
        self.q, self.k, self.v = nn.Linear(dim, dim), nn.Linear(dim, dim), nn.Linear(dim, dim)
        self.temperature = nn.Parameter(torch.tensor(10.0))
        self.ffn = nn.Sequential(nn.Linear(dim, 2 * dim), nn.GELU(), nn.Linear(2 * dim, dim))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = self.norm1(x)
        c = centred(h)
        attention = torch.softmax(self.temperature * l2norm(self.q(c)) @ l2norm(self.k(c)).transpose(-1, -2), dim=-1)
        x = x + attention @ self.v(h)
        return x + self.ffn(self.norm2(x))


class AfAModule(nn.Module):
    """norm(Q) norm(K)^T: the adjacency score in [-1, 1] (paper eq. 2)."""

    def __init__(self, dim: int):
        super().__init__()
        self.norm = nn.LayerNorm(dim)
        self.q, self.k = nn.Linear(dim, dim), nn.Linear(dim, dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h = centred(self.norm(x))
        return l2norm(self.q(h)) @ l2norm(self.k(h)).transpose(-1, -2)


class AfANet(nn.Module):
    def __init__(self, config: AfANetConfig = AfANetConfig()):
        super().__init__()
        if not (config.use_global or config.use_local):
            raise ValueError("AfANet needs the global feature, the local feature, or both")
        self.config = config
        c = config
        self.global_encoder = ConvEncoder(c.in_channels, c.encoder_widths, c.feature) if c.use_global else None
        self.local_encoder = ConvEncoder(c.in_channels, c.encoder_widths, c.feature) if c.use_local else None
        self.project = nn.Linear(c.embedding, c.dim)
        self.position = nn.Sequential(
            nn.Linear(2 + 4 * c.position_frequencies, c.dim), nn.GELU(), nn.Linear(c.dim, c.dim)
        )
        self.register_buffer("frequencies", (2.0 ** torch.arange(c.position_frequencies)) * torch.pi, persistent=False)
        self.blocks = nn.ModuleList(AttentionModule(c.dim) for _ in range(c.layers))
        self.afa = AfAModule(c.dim)
        self.logit_scale = nn.Parameter(torch.tensor(8.0))  # score in [-1, 1] -> BCE logit
        self.logit_bias = nn.Parameter(torch.tensor(-4.0))

    def views(self, tensor: torch.Tensor, vertices: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """What the rest of the network sees of a (6, H, W) tensor and its (M, 2) pixel (col, row)
        vertices: the tensor resized to ``global_size`` (1, 6, g, g), the (M, 6, roi, roi) windows
        around the vertices, and the vertices normalised by the tensor's size (M, 2). A branch that
        is off gets an empty view. Kept apart so that the ONNX engine can take the views from
        PyTorch, whose ``grid_sample`` is 2.5x faster than ONNX Runtime's GridSample."""
        c = self.config
        height, width = tensor.shape[-2:]
        m = vertices.shape[0]
        if self.global_encoder is not None:
            small = F.interpolate(
                tensor[None], size=(c.global_size, c.global_size), mode="bilinear", align_corners=False
            )
        else:
            small = tensor.new_zeros((1, tensor.shape[0], 0, 0))
        if self.local_encoder is not None and m:
            rois = crop_rois(tensor, vertices, c.roi)
        else:
            rois = tensor.new_zeros((m, tensor.shape[0], c.roi, c.roi))
        scale = torch.tensor([width, height], dtype=tensor.dtype, device=tensor.device)
        return small, rois, vertices.to(tensor.dtype) / scale

    def embed_views(self, small: torch.Tensor, rois: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
        """The :meth:`views` -> (M, embedding) vertex embeddings: global feature, local feature, xy."""
        m = xy.shape[0]
        parts = []
        if self.global_encoder is not None:
            parts.append(self.global_encoder(small).expand(m, -1))
        if self.local_encoder is not None:
            parts.append(self.local_encoder(rois) if m else xy.new_zeros((0, self.config.feature)))
        parts.append(xy)
        return torch.cat(parts, dim=1)

    def embed(self, tensor: torch.Tensor, vertices: torch.Tensor) -> torch.Tensor:
        """(6, H, W) tensor and (M, 2) pixel (col, row) vertices -> (M, embedding) vertex embeddings."""
        return self.embed_views(*self.views(tensor, vertices))

    def forward(self, tensor: torch.Tensor, vertices: torch.Tensor) -> torch.Tensor:
        """Adjacency logits (M, M) for the vertices of one patch."""
        m = vertices.shape[0]
        if m == 0:
            return tensor.new_zeros((0, 0))
        return self.logits_from_views(*self.views(tensor, vertices))

    def logits_from_views(self, small: torch.Tensor, rois: torch.Tensor, xy: torch.Tensor) -> torch.Tensor:
        """Adjacency logits (M, M) from the :meth:`views` of M >= 1 vertices."""
        x = self.decoder_input(self.embed_views(small, rois, xy))[None]
        for block in self.blocks:
            x = block(x)
        return self.logit_scale * self.afa(x)[0] + self.logit_bias

    def decoder_input(self, embedding: torch.Tensor) -> torch.Tensor:
        """(M, 2050) embeddings -> (M, dim) decoder tokens: a linear projection of the whole
        embedding plus a learned positional encoding of its normalised (x, y) (last 2 values).

        Not in the paper: the image features of nearby vertices are nearly alike, and the two raw
        coordinates are drowned among 2048 feature values, so the decoder could not tell
        vertices apart (it did not even overfit one patch). Multi-scale sin/cos features of (x, y)
        (Tancik et al. 2020) through a small MLP, added as in transformers, fix that.
        """
        tokens = self.project(embedding)
        xy = embedding[:, -2:]
        features = [xy]
        if self.config.position_frequencies:
            angles = xy[:, :, None] * self.frequencies  # (M, 2, F)
            features += [torch.sin(angles).flatten(1), torch.cos(angles).flatten(1)]
        return tokens + self.position(torch.cat(features, dim=1))

    @torch.no_grad()
    def adjacency(self, tensor: torch.Tensor, vertices: torch.Tensor) -> torch.Tensor:
        """Symmetrised adjacency probabilities (M, M) with a zero diagonal."""
        return adjacency_from_logits(self.forward(tensor, vertices))


def adjacency_from_logits(logits: torch.Tensor) -> torch.Tensor:
    """(M, M) logits -> symmetrised probabilities with a zero diagonal (whichever engine ran)."""
    p = torch.sigmoid(logits)
    p = (p + p.T) / 2
    return p * (1 - torch.eye(p.shape[0], device=p.device, dtype=p.dtype))


def crop_rois(tensor: torch.Tensor, vertices: torch.Tensor, size: int) -> torch.Tensor:
    """(M, C, size, size) windows of ``tensor`` (C, H, W) centred on (col, row) ``vertices``,
    sampled bilinearly (at pixel centres for odd ``size`` and a vertex on a pixel centre), zero
    beyond the edges (works on any device)."""
    c, height, width = tensor.shape
    m = vertices.shape[0]
    offsets = (
        torch.arange(size, device=tensor.device, dtype=tensor.dtype) - (size - 1) / 2
    )  # symmetric about the vertex
    cols = vertices[:, 0, None].to(tensor.dtype) + offsets[None, :]  # (M, size)
    rows = vertices[:, 1, None].to(tensor.dtype) + offsets[None, :]
    gx = (cols / width) * 2 - 1  # align_corners=False: pixel centre (c + 0.5) <-> ((c + 0.5)/W)*2-1
    gy = (rows / height) * 2 - 1
    grid = torch.stack([gx[:, None, :].expand(m, size, size), gy[:, :, None].expand(m, size, size)], dim=-1)
    grid = grid.reshape(1, m * size, size, 2)
    out = F.grid_sample(tensor[None], grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    return out.reshape(c, m, size, size).permute(1, 0, 2, 3)


def edges_from_adjacency(
    probabilities: torch.Tensor, threshold: float = 0.5, max_degree: int | None = 2, fixed: list[tuple[int, int]] = ()
) -> list[tuple[int, int]]:
    """Edges whose symmetric probability exceeds ``threshold``, besides the ``fixed`` ones (corner
    edges, which bypass AfANet). With ``max_degree`` (road boundaries are polylines: 2), edges
    are taken greedily by probability and skipped when either end already has that many edges,
    fixed edges counted first."""
    p = probabilities.detach().cpu()
    m = p.shape[0]
    degree = [0] * m
    chosen = {tuple(sorted(e)) for e in fixed}
    for u, v in chosen:
        degree[u] += 1
        degree[v] += 1
    iu = torch.triu_indices(m, m, offset=1)
    scores = p[iu[0], iu[1]]
    keep = scores > threshold
    pairs = iu[:, keep].T.tolist()
    for k in torch.argsort(scores[keep], descending=True).tolist():
        u, v = pairs[k]
        if (u, v) in chosen:
            continue
        if max_degree is None or (degree[u] < max_degree and degree[v] < max_degree):
            chosen.add((u, v))
            degree[u] += 1
            degree[v] += 1
    return sorted(chosen)
