"""course.style: Gram matrices of random multi-scale features, the style loss, texture synthesis from them
(the building blocks of lecture 11's style transfer), and the procedural style images."""
import pytest
import torch

from course.style import RandomFeatures, dots, gram_matrix, marble, stripes, style_loss, synthesize_texture


def test_gram_matrix_is_symmetric_and_does_not_depend_on_the_image_size():
    net = RandomFeatures(seed=1, dtype=torch.float64)
    image = marble(32, seed=3, dtype=torch.float64)
    tiled = image.repeat(2, 2, 1)                                           # the same texture, 4x the pixels
    for g, h in zip(net(image), net(tiled)):                                # circular padding: exact tiling
        torch.testing.assert_close(g, g.T)
        torch.testing.assert_close(g, h, rtol=1e-10, atol=1e-12)
    f = torch.randn(5, 7, 9, dtype=torch.float64)
    torch.testing.assert_close(gram_matrix(f), torch.einsum("ihw,jhw->ij", f, f) / 63)


def test_random_features_are_seeded_and_count_their_blocks():
    a, b, c = RandomFeatures(seed=0), RandomFeatures(seed=0), RandomFeatures(seed=1)
    image = stripes(32)
    ga, gb, gc = a(image), b(image), c(image)
    assert len(ga) == 1 + a.scales * len(a.sizes) and ga[0].shape == (4, 4) and ga[1].shape == (48, 48)
    assert all(torch.equal(x, y) for x, y in zip(ga, gb))
    assert not torch.equal(ga[1], gc[1])
    assert float(ga[0][3, 3]) == pytest.approx(1.0)                        # the constant channel
    torch.testing.assert_close(ga[0][3, :3], image.mean((0, 1)))            # the mean colour


def test_style_loss_is_zero_on_itself_and_relative_per_block():
    net = RandomFeatures(seed=0, dtype=torch.float64)
    g = net(dots(32, dtype=torch.float64))
    assert float(style_loss(g, g)) == 0.0
    doubled = [2 * x for x in g]                                            # every block off by its own size
    assert float(style_loss(doubled, g)) == pytest.approx(len(g))
    with pytest.raises(ValueError, match="equally long"):
        style_loss(g[:2], g)


def test_synthesis_reproduces_the_stripes_frequency_and_colours():
    """A texture synthesised from stripes has the stripes' dominant frequency and mean colour."""
    style = stripes(32, period=8.0, angle=30.0)
    texture, losses = synthesize_texture(style, (32, 32), steps=150, seed=0)
    assert texture.shape == (32, 32, 3) and bool(((texture >= 0) & (texture <= 1)).all())
    assert float(losses[-1]) < float(losses[0]) / 20

    def peak(image):
        g = image.double().mean(-1)
        spectrum = torch.fft.fft2(g - g.mean()).abs()
        k = int(spectrum.reshape(-1).argmax())
        ky, kx = divmod(k, 32)
        return sorted([(min(ky, 32 - ky), min(kx, 32 - kx))])[0]           # up to the conjugate's sign
    assert peak(texture) == peak(style)
    torch.testing.assert_close(texture.mean((0, 1)), style.mean((0, 1)), atol=0.05, rtol=0)


def test_style_images_and_bad_input():
    for image in (stripes(40), dots(40), marble(40, seed=2)):
        assert image.shape == (40, 40, 3) and bool(((image >= 0) & (image <= 1)).all())
    assert torch.equal(marble(40, seed=2), marble(40, seed=2)) and not torch.equal(marble(40, seed=2), marble(40))
    net = RandomFeatures()
    with pytest.raises(ValueError, match="odd"):
        RandomFeatures(sizes=(3, 4))
    with pytest.raises(ValueError, match=r"\(H, W, 3\)"):
        net(torch.rand(32, 32))
    with pytest.raises(ValueError, match="too small"):
        net(torch.rand(12, 12, 3))
    with pytest.raises(ValueError, match="NaN"):
        net(torch.full((32, 32, 3), float("nan")))
