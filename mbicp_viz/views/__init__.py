"""What a person sees: the scene mapping (``scene``), text (``text``), and its front ends: rerun
recordings (``rrd``) and the viser debugger (``debugger``)."""
