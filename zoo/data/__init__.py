"""CrafterPlay: expert episodes as WebDataset shards (generation, reading, noop filtering).

Import from the submodules (``zoo.data.reader``, ``zoo.data.noop``, ...): this package file stays
empty so that ``zoo --help`` does not load webdataset (and with it torch).
"""
