"""Docstring examples run as tests."""

import doctest

import tiv_model


def test_package_docstring_example():
    result = doctest.testmod(tiv_model, verbose=False)
    assert result.attempted >= 1 and result.failed == 0
