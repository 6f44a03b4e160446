"""Webots support (for users who have Webots; not exercised in CI).

- :mod:`.world`: writes a ``.wbt`` world for a scenario (``pirl webots-world``).
- :mod:`.controller`: the Mavic 2 Pro controller that flies a PIRL policy in it.
- :mod:`.pilot`: the controller's flight law, pure arithmetic (tested without Webots).
"""
