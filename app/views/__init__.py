"""The studio's central tabs: pair, product, sequence, retrieval and compare views."""
