# omni-live's tests: a ROS-free DDS peer (Cyclone DDS's Python binding, which carries its own
# library) and a Foxglove WebSocket client, in a network namespace (util-linux unshare, iproute2).
need_apt util-linux iproute2
need_pip cyclonedds websockets protobuf
