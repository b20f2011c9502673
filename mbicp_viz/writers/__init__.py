"""Files the tool writes for others to read: bags a robot could have recorded."""
