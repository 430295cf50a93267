"""Fast-SCNN (Poudel et al., 2019) and the Res2Net-GFE variant, one-channel (luma) input.

Layout (strides relative to the input):
  LDS   conv3x3 32 s2 -> DSConv 48 s2 -> DSConv 64 s2                        (1/8,  64 ch)
  GFE   bottleneck 64 (x3, s2, t6) -> 96 (x3, s2, t6) -> 128 (x3, s1, t6)     (1/32, 128 ch)
        ('res2net': Res2Net blocks replace the bottlenecks, see Res2NetBlock)
  PPM   bins 1,2,3,6: avgpool -> 1x1 conv 32 -> bilinear up; concat with input -> 1x1 conv 128
  FFM   low-res: bilinear up x4 -> depthwise 3x3 -> 1x1 conv 128 (BN)
        high-res (LDS output): 1x1 conv 128 (BN); add; ReLU                    (1/8, 128 ch)
  CLS   DSConv 128, DSConv 128, (dropout), 1x1 conv -> classes; bilinear up x8

Every convolution is Conv+BN(+ReLU) (`ConvBN`), so BatchNorm folds into the conv at export
(`fold_bn`). All resizes are bilinear with align_corners=False, i.e. ONNX
coordinate_transformation_mode 'half_pixel' (the exporter may write 'pytorch_half_pixel', which
is identical whenever the output extent is > 1, as here).

PPM pooling is `fixed_bin_avgpool`: for bin count b on an h x w map the window is
kh x kw = ceil(h/b) x ceil(w/b) with the same stride, giving ceil(h/kh) x ceil(w/kw) (<= b x b)
bins; the map is padded with zeros on the bottom/right so the last window is whole, and each
window is divided by its number of *valid* (unpadded) elements. When b divides h and w this is
exactly adaptive average pooling (b x b bins); otherwise it is still
exactly one ONNX AveragePool (asymmetric pads, count_include_pad=0), which the training forward
computes too, so training, export and the int8 engine agree at every input size. It exports via
a custom symbolic (TorchScript exporter, dynamo=False).
"""

from __future__ import annotations

import math

import torch
import torch.nn as nn
import torch.nn.functional as F

NUM_CLASSES = 11
IGNORE_INDEX = 11


class IBN(nn.Module):
    """IBN-a normalisation (Pan et al., ECCV 2018): InstanceNorm (affine) on the first half of the
    channels, BatchNorm on the rest. Per-image statistics take each image's exposure and contrast
    out of the shallow features, which IBN-Net found to carry appearance rather than content and
    to be what fails to transfer across domains. Training only: the int8 core has no instance
    normalisation, and it does not fold into the conv."""

    def __init__(self, c):
        super().__init__()
        self.n_in = c // 2
        self.inorm = nn.InstanceNorm2d(self.n_in, affine=True)
        self.bn = nn.BatchNorm2d(c - self.n_in)

    def forward(self, x):
        a, b = torch.split(x, [self.n_in, x.shape[1] - self.n_in], dim=1)
        return torch.cat([self.inorm(a), self.bn(b)], dim=1)


class ConvBN(nn.Sequential):
    """Conv2d (no bias) + BatchNorm2d (+ ReLU). Folded to one Conv (with bias) by fold_bn.
    ibn=True: IBN instead of BatchNorm (not folded; training-only variants)."""

    def __init__(self, cin, cout, k=1, stride=1, groups=1, relu=True, dilation=1, ibn=False):
        pad = dilation * (k - 1) // 2
        layers = [
            nn.Conv2d(cin, cout, k, stride, pad, dilation=dilation, groups=groups, bias=False),
            IBN(cout) if ibn else nn.BatchNorm2d(cout),
        ]
        if relu:
            layers.append(nn.ReLU(inplace=True))
        super().__init__(*layers)


def dsconv(cin, cout, stride=1, ibn=False):
    """Depthwise-separable conv: depthwise 3x3 (BN, ReLU) + pointwise 1x1 (BN or IBN, ReLU)."""
    return nn.Sequential(ConvBN(cin, cin, 3, stride, groups=cin), ConvBN(cin, cout, 1, ibn=ibn))


class Bottleneck(nn.Module):
    """MobileNetV2 inverted residual: 1x1 expand (t), depthwise 3x3 (stride), 1x1 linear project."""

    def __init__(self, cin, cout, stride, t=6):
        super().__init__()
        hid = cin * t
        self.block = nn.Sequential(
            ConvBN(cin, hid, 1),
            ConvBN(hid, hid, 3, stride, groups=hid),
            ConvBN(hid, cout, 1, relu=False),
        )
        self.residual = stride == 1 and cin == cout

    def forward(self, x):
        y = self.block(x)
        return x + y if self.residual else y


class Res2NetBlock(nn.Module):
    """Res2Net-style hierarchical multi-scale block (Gao et al., 2019) built from int8-friendly ops.

    1x1 conv cin -> width*scales (BN, ReLU), split into `scales` groups x_1..x_s of `width` channels
      (built as `scales` separate 1x1 convs cin -> width, the same thing without a Split op);
      stride 1 ('normal'): y_1 = x_1, y_i = K_i(x_i + y_{i-1})  (i >= 2)
      stride 2 ('stage') : y_i = K_i(x_i) for every i (the spatial size changes, so no hierarchy;
                           Res2Net's avg-pooled last split is replaced by a K, to keep the op set small)
    K_i = depthwise 3x3 (stride, BN, ReLU) + pointwise 1x1 width->width (BN, ReLU).
    concat(y_1..y_s) -> 1x1 conv -> cout (BN); + x when stride 1 and cin == cout; ReLU.
    """

    def __init__(self, cin, cout, stride, width, scales=4):
        super().__init__()
        self.scales, self.width, self.stride = scales, width, stride
        self.reduce = nn.ModuleList(ConvBN(cin, width, 1) for _ in range(scales))
        self.stage = stride != 1 or cin != cout
        n_k = scales if self.stage else scales - 1
        self.convs = nn.ModuleList(
            nn.Sequential(ConvBN(width, width, 3, stride, groups=width), ConvBN(width, width, 1))
            for _ in range(n_k)
        )
        self.expand = ConvBN(width * scales, cout, 1, relu=False)
        self.residual = stride == 1 and cin == cout
        self.relu = nn.ReLU(inplace=True)

    def forward(self, x):
        xs = [r(x) for r in self.reduce]
        ys = []
        if self.stage:
            for i in range(self.scales):
                ys.append(self.convs[i](xs[i]))
        else:
            ys.append(xs[0])
            for i in range(1, self.scales):
                inp = xs[i] if i == 1 else xs[i] + ys[-1]
                ys.append(self.convs[i - 1](inp))
        y = self.expand(torch.cat(ys, dim=1))
        if self.residual:
            y = y + x
        return self.relu(y)


# ----------------------------------------------------------------------------------------------
# PPM pooling: one AveragePool with asymmetric zero pads and count_include_pad=0
# ----------------------------------------------------------------------------------------------


def _bin_geometry(h, w, b):
    """Window (= stride) ceil(side/b); ceil(side/window) <= b windows, the last one may be partial.

    Zero pads on the bottom/right make the last window whole; they are never a whole window.
    """
    kh, kw = math.ceil(h / b), math.ceil(w / b)
    return kh, kw, math.ceil(h / kh) * kh - h, math.ceil(w / kw) * kw - w


class _FixedBinAvgPool(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x, b):
        h, w = int(x.shape[2]), int(x.shape[3])
        kh, kw, ph, pw = _bin_geometry(h, w, b)
        return _fixed_bin_avgpool_impl(x, kh, kw, ph, pw)

    @staticmethod
    def symbolic(g, x, b):
        sizes = x.type().sizes()
        h, w = int(sizes[2]), int(sizes[3])
        kh, kw, ph, pw = _bin_geometry(h, w, b)
        return g.op(
            "AveragePool",
            x,
            kernel_shape_i=[kh, kw],
            strides_i=[kh, kw],
            pads_i=[0, 0, ph, pw],
            count_include_pad_i=0,
        )


def _fixed_bin_avgpool_impl(x, kh, kw, ph, pw):
    if ph == 0 and pw == 0:
        return F.avg_pool2d(x, (kh, kw), (kh, kw))
    xp = F.pad(x, (0, pw, 0, ph))
    s = F.avg_pool2d(xp, (kh, kw), (kh, kw)) * (kh * kw)
    ones = torch.ones(1, 1, x.shape[2], x.shape[3], dtype=x.dtype, device=x.device)
    cnt = F.avg_pool2d(F.pad(ones, (0, pw, 0, ph)), (kh, kw), (kh, kw)) * (kh * kw)
    return s / cnt


def fixed_bin_avgpool(x, b):
    """Up to b x b output bins; equals adaptive_avg_pool2d(x, b) when b divides both sides."""
    if torch.onnx.is_in_onnx_export():
        return _FixedBinAvgPool.apply(x, b)
    h, w = int(x.shape[2]), int(x.shape[3])
    kh, kw, ph, pw = _bin_geometry(h, w, b)
    return _fixed_bin_avgpool_impl(x, kh, kw, ph, pw)


def upsample(x, size):
    return F.interpolate(x, size=(int(size[0]), int(size[1])), mode="bilinear", align_corners=False)


class PPM(nn.Module):
    def __init__(self, cin, cout, bins=(1, 2, 3, 6)):
        super().__init__()
        self.bins = bins
        inter = cin // 4
        self.stages = nn.ModuleList(ConvBN(cin, inter, 1) for _ in bins)
        self.out = ConvBN(cin + inter * len(bins), cout, 1)

    def forward(self, x):
        size = (int(x.shape[2]), int(x.shape[3]))
        feats = [x]
        for b, conv in zip(self.bins, self.stages):
            feats.append(upsample(conv(fixed_bin_avgpool(x, b)), size))
        return self.out(torch.cat(feats, dim=1))


class FFM(nn.Module):
    def __init__(self, c_high, c_low, cout, dilation=1):
        super().__init__()
        # The paper's table lists the depthwise conv with dilation; the usual reference
        # implementations use dilation 1. Default 1 (plain depthwise conv in the engine).
        self.dw = ConvBN(c_low, c_low, 3, groups=c_low, dilation=dilation)
        self.low = ConvBN(c_low, cout, 1, relu=False)
        self.high = ConvBN(c_high, cout, 1, relu=False)
        self.relu = nn.ReLU(inplace=True)

    def forward(self, high, low):
        low = upsample(low, high.shape[2:])
        low = self.low(self.dw(low))
        return self.relu(self.high(high) + low)


class FastSCNN(nn.Module):
    """Fast-SCNN; gfe_block='bottleneck' (original) or 'res2net' (the paper's improved variant).

    Input: N x in_ch x H x W, luma scaled to [0, 1] (u8 / 255). Output: N x num_classes x H x W
    logits (or at H/8 x W/8 with final_upsample=False).
    """

    # Res2Net: width*scales (all groups together) per stage, chosen so the total is ~1.27 M.
    R2_WIDTH = {64: 256, 96: 384, 128: 592}  # group widths 64, 96, 148

    def __init__(self, in_ch=1, num_classes=NUM_CLASSES, gfe_block="bottleneck", dropout=0.1,
                 ffm_dilation=1, final_upsample=True, r2_width=None, scales=4, lds_ibn=False):
        super().__init__()
        self.gfe_block = gfe_block
        self.final_upsample = final_upsample
        # lds_ibn: IBN after the first conv and the first DSConv's pointwise conv (not after the
        # last LDS layer, whose output is the FFM's high-resolution input).
        self.lds = nn.Sequential(ConvBN(in_ch, 32, 3, 2, ibn=lds_ibn), dsconv(32, 48, 2, ibn=lds_ibn),
                                 dsconv(48, 64, 2))
        cfg = [(64, 3, 2), (96, 3, 2), (128, 3, 1)]  # (channels, repeats, first stride)
        blocks, cin = [], 64
        widths = dict(self.R2_WIDTH)
        widths.update(r2_width or {})
        for c, n, s in cfg:
            for i in range(n):
                stride = s if i == 0 else 1
                if gfe_block == "bottleneck":
                    blocks.append(Bottleneck(cin, c, stride, t=6))
                elif gfe_block == "res2net":
                    blocks.append(Res2NetBlock(cin, c, stride, widths[c] // scales, scales))
                else:
                    raise ValueError(f"unknown gfe_block {gfe_block!r}")
                cin = c
        self.gfe = nn.Sequential(*blocks)
        self.ppm = PPM(128, 128)
        self.ffm = FFM(64, 128, 128, dilation=ffm_dilation)
        self.cls = nn.Sequential(dsconv(128, 128), dsconv(128, 128))
        self.drop = nn.Dropout(dropout)
        self.head = nn.Conv2d(128, num_classes, 1)

    def forward(self, x):
        size = (int(x.shape[2]), int(x.shape[3]))
        high = self.lds(x)
        low = self.ppm(self.gfe(high))
        y = self.ffm(high, low)
        y = self.head(self.drop(self.cls(y)))
        if self.final_upsample:
            y = upsample(y, size)
        return y


class AuxHeads(nn.Module):
    """Fast-SCNN's auxiliary losses (Poudel et al. 2019, section 4.1: "at the end of the learning
    to downsample and the global feature extraction modules", weight 0.4): a small head (3x3
    ConvBN to 32 channels, dropout, 1x1 conv to the classes) on the LDS output and on the GFE's
    (after the PPM). Training only: the heads live outside the model, read its features through
    forward hooks, and are never exported, so the deployed network is unchanged."""

    def __init__(self, model, num_classes=NUM_CLASSES, dropout=0.1):
        super().__init__()
        self.heads = nn.ModuleList(
            nn.Sequential(ConvBN(c, 32, 3), nn.Dropout(dropout), nn.Conv2d(32, num_classes, 1))
            for c in (64, 128))
        self._feats = {}
        self._hooks = [mod.register_forward_hook(self._keep(i)) for i, mod in enumerate((model.lds, model.ppm))]

    def _keep(self, i):
        def hook(_module, _inputs, out):
            self._feats[i] = out
        return hook

    def forward(self, size):
        """Logits of both heads at `size` for the features of the model's last forward pass."""
        if len(self._feats) != len(self.heads):
            raise RuntimeError("AuxHeads: the model has not run a forward pass since the last call")
        out = [upsample(h(self._feats[i]), size) for i, h in enumerate(self.heads)]
        self._feats.clear()  # release the activations; each call needs a fresh forward pass
        return out


def count_params(model):
    return sum(p.numel() for p in model.parameters())


def count_params_folded(model):
    """Parameters after BN folding (conv weights + one bias per conv output channel)."""
    n = 0
    for m in model.modules():
        if isinstance(m, nn.Conv2d):
            n += m.weight.numel() + m.out_channels
    return n


@torch.no_grad()
def zero_init_residual(model):
    """Zero the BatchNorm scale of the last conv of every residual block (Bottleneck's linear
    projection, Res2NetBlock's expand), so that each block starts as the identity and the deep
    stack trains like a shallow one at first (Goyal et al. 2017). Returns the blocks changed."""
    n = 0
    for m in model.modules():
        if isinstance(m, Bottleneck) and m.residual:
            nn.init.zeros_(m.block[-1][1].weight)
            n += 1
        elif isinstance(m, Res2NetBlock) and m.residual:
            nn.init.zeros_(m.expand[1].weight)
            n += 1
    return n


@torch.no_grad()
def fold_bn(model):
    """Fold every ConvBN's BatchNorm into its conv (in place); returns the model (eval mode)."""
    model.eval()
    for m in model.modules():
        if isinstance(m, ConvBN) and isinstance(m[1], nn.BatchNorm2d):
            conv, bn = m[0], m[1]
            std = torch.sqrt(bn.running_var + bn.eps)
            g = bn.weight / std
            w = conv.weight * g.reshape(-1, 1, 1, 1)
            b = bn.bias - bn.running_mean * g
            if conv.bias is not None:
                b = b + conv.bias * g
            conv.weight.copy_(w)
            conv.bias = nn.Parameter(b)
            m[1] = nn.Identity()
    return model


# The Fast-SCNN variants (deployable: export.py, quantise.py, onnx_to_checkpoint.py, the .slm
# converter); VARIANTS adds the training-only ones train.py also builds: the distillation teacher,
# and the bottleneck with IBN in the LDS (a domain-generalisation experiment; no int8 op for it).
FASTSCNN_VARIANTS = ("res2net", "bottleneck")
VARIANTS = FASTSCNN_VARIANTS + ("bottleneck-ibn", "resunet")


def build(variant, **kw):
    """'res2net' / 'bottleneck': the deployable Fast-SCNN; 'bottleneck-ibn': the bottleneck with
    IBN in the LDS (training only); 'resunet': the distillation teacher."""
    if variant == "resunet":
        from .teacher import ResUNet

        return ResUNet(**kw)
    if variant == "bottleneck-ibn":
        return FastSCNN(gfe_block="bottleneck", lds_ibn=True, **kw)
    return FastSCNN(gfe_block=variant, **kw)


if __name__ == "__main__":
    for v in ("bottleneck", "res2net"):
        for nc in (19, 11):
            m = build(v, num_classes=nc)
            print(f"{v:10s} classes={nc:2d} params={count_params(m):,} folded={count_params_folded(m):,}")
