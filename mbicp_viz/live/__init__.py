"""Live from a robot: a Foxglove WebSocket server's scans matched as they arrive (``mbicp-viz
live``): ``client.py`` speaks the protocol, ``decode.py`` turns its ROS messages into scans and
odometry, ``run.py`` matches, buffers the last seconds and saves them as a bag."""
