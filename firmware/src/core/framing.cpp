#include "framing.h"

#include "crc16.h"

namespace sphere {

size_t cobsEncode(const uint8_t* in, size_t len, uint8_t* out) {
    size_t code_pos = 0, o = 1;
    uint8_t code = 1;
    for (size_t i = 0; i < len; ++i) {
        if (in[i] == 0) {
            out[code_pos] = code;
            code_pos = o++;
            code = 1;
        } else {
            out[o++] = in[i];
            if (++code == 0xFF) {
                out[code_pos] = code;
                code_pos = o++;
                code = 1;
            }
        }
    }
    out[code_pos] = code;
    return o;
}

int cobsDecode(const uint8_t* in, size_t len, uint8_t* out, size_t out_cap) {
    size_t i = 0, o = 0;
    while (i < len) {
        uint8_t code = in[i++];
        if (code == 0) return -1;
        for (uint8_t k = 1; k < code; ++k) {
            if (i >= len) return -1;  // code points past the end of the chunk
            uint8_t b = in[i++];
            if (b == 0 || o >= out_cap) return -1;
            out[o++] = b;
        }
        if (code != 0xFF && i < len) {
            if (o >= out_cap) return -1;
            out[o++] = 0;
        }
    }
    return (int)o;
}

size_t FrameEncoder::encodeWithSeq(uint8_t type, uint8_t seq, const uint8_t* body, uint8_t body_len, uint8_t* out) {
    if (body_len > MAX_BODY) return 0;
    uint8_t payload[MAX_PAYLOAD];
    payload[0] = type;
    payload[1] = seq;
    for (uint8_t i = 0; i < body_len; ++i) payload[2 + i] = body[i];
    uint16_t crc = crc16(payload, (size_t)body_len + 2);
    payload[2 + body_len] = (uint8_t)(crc & 0xFF);
    payload[3 + body_len] = (uint8_t)(crc >> 8);
    size_t n = cobsEncode(payload, (size_t)body_len + 4, out);
    out[n++] = 0;
    return n;
}

size_t FrameEncoder::encode(uint8_t type, const uint8_t* body, uint8_t body_len, uint8_t* out) {
    size_t n = encodeWithSeq(type, seq_, body, body_len, out);
    if (n) ++seq_;
    return n;
}

void FrameDecoder::reset() {
    fill_ = 0;
    len_ = 0;
    overflowed_ = false;
    oversize = framing_errors = crc_errors = 0;
    bytes_skipped = 0;
}

FrameResult FrameDecoder::push(uint8_t byte) {
    if (byte != 0) {
        if (overflowed_) {
            ++bytes_skipped;
            return FRAME_NONE;
        }
        if (fill_ >= MAX_ENCODED) {
            overflowed_ = true;
            ++oversize;
            bytes_skipped += (uint32_t)fill_ + 1;
            fill_ = 0;
            return FRAME_NONE;
        }
        buf_[fill_++] = byte;
        return FRAME_NONE;
    }
    // delimiter
    if (overflowed_) {
        overflowed_ = false;
        ++bytes_skipped;  // the delimiter of the dropped chunk
        return FRAME_OVERSIZE;
    }
    uint8_t n = fill_;
    fill_ = 0;
    if (n == 0) return FRAME_NONE;
    int d = cobsDecode(buf_, n, buf_, sizeof buf_);
    if (d < 4) {
        ++framing_errors;
        bytes_skipped += (uint32_t)n + 1;
        return FRAME_FRAMING_ERROR;
    }
    uint16_t crc = crc16(buf_, (size_t)d - 2);
    uint16_t got = (uint16_t)(buf_[d - 2] | ((uint16_t)buf_[d - 1] << 8));
    if (crc != got) {
        ++crc_errors;
        bytes_skipped += (uint32_t)n + 1;
        return FRAME_CRC_ERROR;
    }
    len_ = (uint8_t)d;
    return FRAME_OK;
}

}  // namespace sphere
