"""``exohil convert``: placeholder replaced below."""
COMMANDS: list = []
