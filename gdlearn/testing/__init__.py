"""Test harnesses shared by the tests, the exercises' checks and the book's figures."""
