"""The recurrent cells against their formulas, with and without autograd."""

import pytest
import torch
import torch.nn.functional as F

from neuspike.nn import ConvLSTM


def _lstm_by_formula(cell: ConvLSTM, x, h, c):
    """The ConvLSTM equations written out, independently of the cell's forward."""
    z = F.conv2d(torch.cat([x, h], dim=1), cell.gates.weight, cell.gates.bias, padding=cell.gates.padding)
    i, f, o, g = z.chunk(4, dim=1)
    c_new = torch.sigmoid(f) * c + torch.sigmoid(i) * torch.tanh(g)
    return torch.sigmoid(o) * torch.tanh(c_new), c_new


@pytest.mark.parametrize("shape", [(1, 3, 8, 16), (2, 5, 7, 13)])  # the second: a batch, odd sizes
def test_conv_lstm_matches_the_formula_with_and_without_autograd_and_leaves_its_state_alone(shape):
    b, cin, hh, ww = shape
    gen = torch.Generator().manual_seed(3)
    cell = ConvLSTM(cin, 6, 3)
    with torch.no_grad():
        for p in cell.parameters():
            p.copy_(torch.randn(p.shape, generator=gen) * 0.3)
    x = torch.randn(b, cin, hh, ww, generator=gen)
    h, c = torch.randn(b, 6, hh, ww, generator=gen), torch.randn(b, 6, hh, ww, generator=gen)
    h0, c0 = h.clone(), c.clone()
    with torch.no_grad():
        want_h, want_c = _lstm_by_formula(cell, x, h, c)
        nograd_h, (same_h, nograd_c) = cell(x, (h, c))
    grad_h, (_, grad_c) = cell(x, (h, c))  # autograd on, as in training
    assert grad_h.requires_grad
    assert same_h is nograd_h
    assert torch.equal(h, h0) and torch.equal(c, c0)  # a cell never writes into the state it was given
    for got_h, got_c in ((nograd_h, nograd_c), (grad_h.detach(), grad_c.detach())):
        assert torch.allclose(got_h, want_h, atol=1e-6, rtol=0)
        assert torch.allclose(got_c, want_c, atol=1e-6, rtol=0)
    assert torch.allclose(nograd_h, grad_h.detach(), atol=1e-6, rtol=0)


def test_conv_lstm_starts_from_zeros():
    gen = torch.Generator().manual_seed(4)
    cell = ConvLSTM(2, 4, 3)
    x = torch.randn(1, 2, 5, 6, generator=gen)
    zeros = torch.zeros(1, 4, 5, 6)
    with torch.no_grad():
        h, (_, c) = cell(x)
        want_h, want_c = _lstm_by_formula(cell, x, zeros, zeros)
    assert torch.allclose(h, want_h, atol=1e-6, rtol=0) and torch.allclose(c, want_c, atol=1e-6, rtol=0)
