// Framing per protocol/spec.md §2: payload = type, seq, body, CRC-16/CCITT-FALSE (little-endian);
// on the wire COBS(payload) followed by one 0x00 delimiter.
#pragma once
#include <stddef.h>
#include <stdint.h>

namespace sphere {

const uint8_t MAX_PAYLOAD = 64;  // type + seq + body + crc
const uint8_t MAX_BODY = MAX_PAYLOAD - 4;
const uint8_t MAX_ENCODED = 65;  // COBS of MAX_PAYLOAD, without delimiter
const uint8_t MAX_FRAME = 66;    // on the wire, with the delimiter

// COBS-encodes `len` bytes into `out` (room for len + len/254 + 1); returns the encoded length
// (no delimiter).
size_t cobsEncode(const uint8_t* in, size_t len, uint8_t* out);
// Decodes one COBS chunk (no delimiter). Returns the decoded length, or -1 when the chunk is not
// valid COBS (a zero byte inside, or a code byte pointing past the end). `out` may equal `in`.
int cobsDecode(const uint8_t* in, size_t len, uint8_t* out, size_t out_cap);

// Builds frames: type, seq, body → COBS(payload) 0x00. Keeps the device's sequence counter.
class FrameEncoder {
public:
    FrameEncoder() : seq_(0) {}
    // Encodes one frame into `out` (at least MAX_FRAME bytes); returns the wire length, 0 when the
    // body is too long. Uses and then advances the sequence counter.
    size_t encode(uint8_t type, const uint8_t* body, uint8_t body_len, uint8_t* out);
    // The same with an explicit sequence number (does not touch the counter).
    static size_t encodeWithSeq(uint8_t type, uint8_t seq, const uint8_t* body, uint8_t body_len, uint8_t* out);
    uint8_t nextSeq() const { return seq_; }
    void setNextSeq(uint8_t s) { seq_ = s; }

private:
    uint8_t seq_;
};

// What FrameDecoder::push reports for a byte.
enum FrameResult : uint8_t {
    FRAME_NONE = 0,       // byte buffered, or an empty chunk
    FRAME_OK,             // a CRC-good payload is ready: payload(), payloadLength()
    FRAME_OVERSIZE,       // more than MAX_ENCODED bytes without a delimiter (reported at its delimiter)
    FRAME_FRAMING_ERROR,  // COBS invalid or payload shorter than 4 bytes
    FRAME_CRC_ERROR,      // CRC mismatch
};

// Receiver side of §2.1: collects bytes up to 0x00, then judges the chunk. Type and length checks
// belong to the layer above (packet tables, CommandParser).
class FrameDecoder {
public:
    FrameDecoder() { reset(); }
    void reset();
    FrameResult push(uint8_t byte);
    const uint8_t* payload() const { return buf_; }
    uint8_t payloadLength() const { return len_; }  // includes type, seq and crc
    uint8_t type() const { return buf_[0]; }
    uint8_t seq() const { return buf_[1]; }
    const uint8_t* body() const { return buf_ + 2; }
    uint8_t bodyLength() const { return (uint8_t)(len_ - 4); }
    // Bytes of an unfinished chunk are buffered (the next 0x00 ends a frame or an error).
    bool pending() const { return fill_ != 0 || overflowed_; }

    // Counters of §2.1 (wrap at 65536).
    uint16_t oversize, framing_errors, crc_errors;
    uint32_t bytes_skipped;

private:
    uint8_t buf_[MAX_ENCODED];
    uint8_t fill_;
    uint8_t len_;
    bool overflowed_;
};

}  // namespace sphere
