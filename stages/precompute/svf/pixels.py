"""The SVF pixel grid's bit-packed images (the package doc: "Pixel grid"): their size, packing and
unpacking."""


import numpy as np
from numba import njit


def packed_bytes(res_theta: int, res_phi: int) -> int:
    """Bytes of one bit-packed image."""
    return (res_theta * res_phi + 7) // 8


def unpack_images(packed, res_theta: int, res_phi: int):
    """(S, res_theta, res_phi) uint8 0/1 from bit-packed images."""
    D = res_theta * res_phi
    return np.unpackbits(np.asarray(packed, np.uint8), axis=1, count=D).reshape(-1, res_theta, res_phi)


def pack_images(images):
    """Bit-packed (S, ceil(D/8)) uint8 from (S, res_theta, res_phi) 0/1 images."""
    a = np.asarray(images, np.uint8)
    return np.packbits(a.reshape(a.shape[0], -1) != 0, axis=1)


@njit(cache=True)
def unpack_into(packed, s, img):
    """Image s of ``packed`` into the flat uint8 array ``img`` (length D)."""
    for i in range(img.shape[0]):
        img[i] = (packed[s, i >> 3] >> (7 - (i & 7))) & 1
