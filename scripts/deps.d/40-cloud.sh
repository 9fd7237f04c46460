# Point-cloud formats and ROS 2 bags (mk/cloud.mk): independent readers from PyPI: plyfile
# (PLY), pypcd4 (PCD), laspy (LAS), rosbags and mcap-ros2-support (rosbag2 / MCAP, CDR
# PointCloud2, Image, CameraInfo), OpenCV (the PNG frames; the same build 50-py.sh installs).
# Open3D is installed only by `make bench` (~0.9 GB with its dependencies).
need_pip numpy pytest plyfile pypcd4 laspy rosbags mcap-ros2-support opencv-contrib-python-headless
