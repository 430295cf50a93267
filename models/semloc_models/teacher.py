"""A larger segmentation network to distil Fast-SCNN from (issue 15: "distillation from a larger
network you train yourselves"). Never deployed: it only labels training crops for the student.

ResUNet: a ResNet-18-shaped encoder (basic blocks, two per stage, widths 64/128/256/512, strides
1/4 .. 1/32 after a two-conv stem at 1/2), Fast-SCNN's pyramid pooling on the 1/32 map, and a
U-Net decoder that upsamples and fuses each encoder stage down to 1/4 (concat + 3x3 conv), then a
1x1 classifier and a bilinear x4. One-channel (luma) input and 11 CamVid classes, like the
student, so the two see the same crops. 13.7 M parameters (13,670,347), 12 times the student.
"""

from __future__ import annotations

import torch
import torch.nn as nn

from .fastscnn import NUM_CLASSES, PPM, ConvBN, upsample


class BasicBlock(nn.Module):
    """ResNet basic block: 3x3 conv (stride) + 3x3 conv, identity or 1x1 projection, ReLU."""

    def __init__(self, cin, cout, stride=1):
        super().__init__()
        self.body = nn.Sequential(ConvBN(cin, cout, 3, stride), ConvBN(cout, cout, 3, relu=False))
        self.short = (ConvBN(cin, cout, 1, stride, relu=False)
                      if stride != 1 or cin != cout else nn.Identity())
        self.relu = nn.ReLU(inplace=True)

    def forward(self, x):
        return self.relu(self.body(x) + self.short(x))


def stage(cin, cout, stride, blocks=2):
    return nn.Sequential(BasicBlock(cin, cout, stride), *[BasicBlock(cout, cout) for _ in range(blocks - 1)])


class ResUNet(nn.Module):
    def __init__(self, in_ch=1, num_classes=NUM_CLASSES, widths=(32, 64, 128, 256, 512), dropout=0.1):
        super().__init__()
        w0, w1, w2, w3, w4 = widths
        self.stem = nn.Sequential(ConvBN(in_ch, w0, 3, 2), ConvBN(w0, w0, 3))  # 1/2
        self.enc1 = stage(w0, w1, 2)  # 1/4
        self.enc2 = stage(w1, w2, 2)  # 1/8
        self.enc3 = stage(w2, w3, 2)  # 1/16
        self.enc4 = stage(w3, w4, 2)  # 1/32
        self.ppm = PPM(w4, 256)
        self.dec3 = nn.Sequential(ConvBN(256 + w3, 192, 3), ConvBN(192, 192, 3))
        self.dec2 = nn.Sequential(ConvBN(192 + w2, 128, 3), ConvBN(128, 128, 3))
        self.dec1 = nn.Sequential(ConvBN(128 + w1, 96, 3), ConvBN(96, 96, 3))
        self.drop = nn.Dropout(dropout)
        self.head = nn.Conv2d(96, num_classes, 1)

    def forward(self, x):
        size = (int(x.shape[2]), int(x.shape[3]))
        e1 = self.enc1(self.stem(x))
        e2 = self.enc2(e1)
        e3 = self.enc3(e2)
        y = self.ppm(self.enc4(e3))
        y = self.dec3(torch.cat([upsample(y, e3.shape[2:]), e3], 1))
        y = self.dec2(torch.cat([upsample(y, e2.shape[2:]), e2], 1))
        y = self.dec1(torch.cat([upsample(y, e1.shape[2:]), e1], 1))
        return upsample(self.head(self.drop(y)), size)
