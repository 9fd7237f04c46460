# The Python package (python/, built with maturin) and its tests, and the batch workflow
# (workflow/, Snakemake): see mk/py.mk. cv2.omnidir (OpenCV's contrib build) is the
# independent reference for the Mei camera model; plyfile an independent PLY reader.
need_pip maturin numpy pytest opencv-contrib-python-headless plyfile snakemake
