//! Point clouds: triangulation, merging, motion compensation, voxel grid, outlier removal, evaluation.
