"""The shipped plugins, installed as the package ``airspace_sim_plugins`` (see
docs/plugins.md). Each module here is also a file to read and copy into your own plugins
folder; the folder scan skips this ``_``-prefixed file."""
