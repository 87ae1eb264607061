"""The studio's central tabs: pair, product, sequence, retrieval and compare views."""

#: the tabs' titles, in order (``corr-studio --tab`` takes one, in any case)
TAB_NAMES = ("Pair", "Product", "Sequence", "Retrieval", "Compare")
