"""Which pixels stop sampling under an error target: an estimate of the standard error of a pixel's mean
that neither trusts one pixel's few samples nor the 1/n of independent samples.

- Scrambled Sobol: the variance of a mean of n samples of a 2-D visibility falls as n^-(1 + decay), decay
  0.5 (Mitchell 1996; docs/choices.md#sobol-variance-decay); 1/n (decay 0) overstates the error and keeps
  pixels sampling that are done. The random sampler takes decay 0.
- Pooled over the 5x5 neighbourhood: a pixel's sample variance is the larger of its own and the mean of
  its hit neighbours' (a pixel whose first samples agreed by chance is seldom surrounded by such pixels).
- Floored by Laplace's rule of succession over the neighbourhood's samples: after k samples an outcome not
  yet seen still has probability 1 / (k + 2), so a sample's variance is at least q (1 - q) for that q.
- Checked when the sample count reaches a power of two (from min_samples on): every power-of-two prefix of
  the Sobol sequence is a stratified net, where the decay holds. A check after n samples sees each
  neighbour as it was after min(its samples, n), so a frame continued from the last one's pixels
  (pixel_reuse.py) stops the same pixels as a full render: the renderer keeps each pixel's variance at
  every check it passed, and samples again the kept pixels within dependence_radius of a changed one.
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


def checks(min_samples, samples):
    """The sample counts at which pixels are checked in a render of `samples` samples (is_check)."""
    out, n = [], next_check(0, min_samples)
    while n <= samples:
        out.append(n)
        n *= 2
    return out


def sample_variances(sums, sq_sums, counts):
    """(M,) each pixel's unbiased sample variance of its grey value (0 below two samples); sums (M, 3),
    sq_sums (M,) of the grey value, counts (M,) samples taken."""
    n = np.maximum(counts.astype(np.float64), 1.0)
    mean = sums.mean(axis=1) / n
    var = np.maximum(sq_sums / n - mean * mean, 0.0) * n / np.maximum(n - 1.0, 1.0)
    var[counts < 2] = 0.0
    return var


def standard_errors(width, height, pixels, variances, counts, decay):
    """(M,) the estimated standard error of each hit pixel's mean (module docstring); pixels (M,) flat
    image indices, variances (M,) their sample variances (sample_variances), counts (M,) their samples."""
    n = counts.astype(np.float64)
    around = [_box_sum(_image(width, height, pixels, v)) for v in (variances, (n > 0).astype(np.float64), n)]
    var_sum, sampled, samples = (a.reshape(-1)[pixels] for a in around)
    q = 1.0 / (samples + 2.0)
    var = np.maximum(np.maximum(variances, var_sum / np.maximum(sampled, 1.0)), q * (1.0 - q))
    return np.sqrt(var / np.maximum(n, 1.0) ** (1.0 + decay))


def dependence_radius(min_samples, samples):
    """How far (in pixels, either axis) another pixel can change a pixel's stop count in a render of
    `samples` samples: each check reads the 5x5 neighbourhood, whose own stop counts came from theirs."""
    return WINDOW_RADIUS * len(checks(min_samples, samples))


def near(mask, radius):
    """Whether each pixel of the (H, W) bool image `mask` is within `radius` pixels (either axis) of a True one."""
    return _box_sum(mask.astype(np.float64), radius) > 0.5


def _image(width, height, pixels, values):
    """values scattered to their pixels of an (H, W) image of zeros."""
    img = np.zeros(width * height)
    img[pixels] = values
    return img.reshape(height, width)


def _box_sum(img, r=WINDOW_RADIUS):
    """Each pixel's sum over its (2r+1)^2 window (zero outside the image), in a fixed order of its own window's
    values (rows, then columns): unlike a summed-area table, whose rounding carries the whole image, a pixel's
    sum depends on its window only, so a continued frame's decisions are a full render's bit for bit."""
    height, width = img.shape
    padded = np.pad(img, r)
    rows = padded[:, 0:width].copy()
    for dx in range(1, 2 * r + 1):
        rows += padded[:, dx:dx + width]
    out = rows[0:height].copy()
    for dy in range(1, 2 * r + 1):
        out += rows[dy:dy + height]
    return out
