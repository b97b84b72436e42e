"""Evaluate stage: image error metrics (RMSE, relative MSE, SSIM, CIEDE2000, mean intensity).

``stages.evaluate.metrics`` holds the kernels; ``pipeline.runners.evaluate`` reads images and
render artifacts, ``pipeline.report`` draws pictures and writes the report.
"""
