# omni-calib interop tests (mk/calib.mk): OpenCV's omnidir module (cv2.omnidir, in the contrib
# build) is the independent reference for the exported and imported OpenCV/Kalibr files; PyYAML
# reads and writes camchain.yaml as Kalibr does.
need_pip numpy opencv-contrib-python-headless pyyaml
