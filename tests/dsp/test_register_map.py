"""The register map type (dsp.register_map): names, addresses, widths and the one write
check shared by every front end."""
import pytest

from dsp.register_map import Register, RegisterMap

MAP = RegisterMap("test", (Register("freq", 0, 8), Register("mode", 2, 3, minimum=1, maximum=5),
                           Register("gain", 3, 6, True), Register("k", 5, 8, True, -7, 7, 2)))


def test_names_addresses_widths():
    assert MAP.names == {"freq": 0, "mode": 2, "gain": 3, "k": 5}
    assert MAP.address("mode") == 2 and MAP.width(3) == 6 and MAP.width(5) == 8
    assert MAP["k"].part_width == 4 and MAP["k"].bounds == (-7, 7)
    assert MAP["gain"].bounds == (-32, 31)
    with pytest.raises(KeyError, match="test registers are freq, mode, gain, k, not 'x'"):
        MAP.address("x")
    with pytest.raises(ValueError, match="test register address must be one of 0, 2, 3, 5, "
                                         "not 1"):
        MAP.width(1)


def test_check_write():
    assert MAP.check_write(0, 255) == 255
    assert MAP.check_write(2, 5) == 5
    assert MAP.check_write(3, 0b100000) == 32            # -32, as its bits
    assert MAP.check_write(5, 0x97) == 0x97              # re 7, im -7
    bad = [(0, 256, r"freq \(address 0\) takes unsigned 8-bit words in \[0, 255\], not 256"),
           (0, -1, r"freq \(address 0\) takes .*, not -1"),
           (0, 1.5, r"freq .* not 1.5"), (0, True, r"freq .* not True"),
           (2, 0, r"mode \(address 2\) takes unsigned 3-bit words in \[1, 5\], not 0"),
           (2, 6, r"mode .* not 6"),
           (3, 64, r"gain \(address 3\) takes 6-bit two's complement words in \[-32, 31\], "
                   r"not 64"),
           (5, 0x08, r"k \(address 5\) takes 8-bit words of 2 two's complement 4-bit parts "
                     r"\(LSB first\), each in \[-7, 7\], not 8"),
           (5, 0x80, r"k .* not 128"),
           (7, 0, r"test register address must be one of 0, 2, 3, 5, not 7")]
    for a, v, msg in bad:
        with pytest.raises(ValueError, match=msg):
            MAP.check_write(a, v)


@pytest.mark.parametrize("regs, msg", [
    ((Register("a", 0, 4), Register("a", 1, 4)), r"test register names must be unique"),
    ((Register("a", 0, 4), Register("b", 0, 4)), r"test register addresses must be unique"),
    ((Register("a", 0, 0),), r"test register a width must be an int >= 1, not 0"),
    ((Register("a", -1, 4),), r"test register a address must be an int >= 0, not -1"),
    ((Register("a", 0, 5, parts=2),), r"width 5 must be a multiple of its 2 parts"),
    ((Register("a", 0, 4, minimum=9, maximum=8),), r"a range \[9, 8\] must be non-empty "
                                                   r"and within its bits' \[0, 15\]"),
    ((Register("a", 0, 4, True, -9),), r"range \[-9, 7\] must be .* \[-8, 7\]"),
    ((Register("a", 0, 4, maximum=16),), r"range \[0, 16\] must be"),
    ((("a", 0),), r"test registers must be Register tuples"),
])
def test_bad_maps(regs, msg):
    with pytest.raises(ValueError, match=msg):
        RegisterMap("test", regs)
