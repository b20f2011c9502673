"""The interactive debugger: the model of a tab (``state``), its panels, their wiring
(``session``) and the server (``app``)."""
