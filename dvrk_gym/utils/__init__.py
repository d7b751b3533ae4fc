"""Small helpers with no simulator knowledge: torch thread counts, cached run folders, the package's source fingerprint."""
