"""The preview renderer: ambient occlusion and direct light with shadows, sampled progressively
(preview_render.py: `PreviewRender`, `render_preview`, configured by render_options.py's
`RenderOptions`). The camera makes the primary rays (camera.py); the sampling kernel adds AO and light
samples per pixel (render_kernels.py) from Owen-scrambled Sobol points (sampling.py), cosine-weighted
hemisphere and light sampling (shading.py) and the packed lights (lights.py); denoise.py filters the
estimate (edge-avoiding à-trous, variance-guided) and pixel_reuse.py carries unaffected pixels over
from the frame before.
"""
