"""Which pixels stop sampling under an error target: an estimate of the standard error of a pixel's mean
that neither trusts one pixel's few samples nor the 1/n of independent samples.

- Scrambled Sobol: the variance of a mean of n samples of a 2-D visibility falls as n^-(1 + decay), decay
  0.5 (Mitchell 1996; docs/choices.md#sobol-variance-decay); 1/n (decay 0) overstates the error 2-3x and
  keeps pixels sampling that are done. The random sampler takes decay 0.
- Pooled over the 5x5 neighbourhood: a pixel's sample variance is the larger of its own and the mean of
  its hit neighbours' (a pixel whose first samples agreed by chance is seldom surrounded by such pixels).
- Floored by Laplace's rule of succession over the neighbourhood's samples: after k samples an outcome not
  yet seen still has probability 1 / (k + 2), so a sample's variance is at least q (1 - q) for that q.
- Checked when the sample count reaches a power of two (from min_samples on): every power-of-two prefix of
  the Sobol sequence is a stratified net, where the decay holds.
docs/choices.md#adaptive-sampling-by-a-pooled-sobol-error says what was measured.
"""
import numpy as np

WINDOW_RADIUS = 2  # the 5x5 neighbourhood


def is_check(samples, min_samples):
    """Whether pixels are checked after `samples` samples: a power of two, at least min_samples."""
    return samples >= min_samples and samples & (samples - 1) == 0


def next_check(samples, min_samples):
    """The first sample count after `samples` at which pixels are checked (is_check)."""
    check = 1 << max(int(min_samples) - 1, 0).bit_length()
    while check <= samples:
        check *= 2
    return check


def standard_errors(width, height, pixels, sums, sq_sums, counts, decay):
    """(M,) the estimated standard error of each hit pixel's mean (module docstring); pixels (M,) flat
    image indices, sums (M, 3), sq_sums (M,) of the grey value, counts (M,) samples taken."""
    n = counts.astype(np.float64)
    taken = np.maximum(n, 1.0)
    mean = sums.mean(axis=1) / taken
    own = np.maximum(sq_sums / taken - mean * mean, 0.0) * taken / np.maximum(taken - 1.0, 1.0)
    own[n < 2] = 0.0
    around = [_box_sum(_image(width, height, pixels, v)) for v in (own, (n > 0).astype(np.float64), n)]
    var_sum, sampled, samples = (a.reshape(-1)[pixels] for a in around)
    q = 1.0 / (samples + 2.0)
    var = np.maximum(np.maximum(own, var_sum / np.maximum(sampled, 1.0)), q * (1.0 - q))
    return np.sqrt(var / taken ** (1.0 + decay))


def _image(width, height, pixels, values):
    """values scattered to their pixels of an (H, W) image of zeros."""
    img = np.zeros(width * height)
    img[pixels] = values
    return img.reshape(height, width)


def _box_sum(img, r=WINDOW_RADIUS):
    """Each pixel's sum over its (2r+1)^2 window (zero outside the image), by summed-area table."""
    c = np.pad(img, ((r + 1, r), (r + 1, r))).cumsum(0).cumsum(1)
    k = 2 * r + 1
    return c[k:, k:] - c[:-k, k:] - c[k:, :-k] + c[:-k, :-k]
