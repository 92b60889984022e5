/* amsfe_cdr.h: the four message types of amsfe's live topics in their wire form (CDR,
 * little endian, XCDR1: what rmw_fastrtps_cpp sends), read and written in buffers the node
 * allocates once, so that taking a sample and publishing a command allocate nothing
 * (rcl_take_serialized_message / rcl_publish_serialized_message; the typed rcl_take frees
 * and allocates every sequence of a JointState at each message).
 *
 * Offsets are relative to the payload (after the 4-byte encapsulation header); a primitive
 * of size s starts at a multiple of s (8 at most).  tests/test_cnode.py checks both
 * directions against rclpy's serialize_message / deserialize_message.
 *
 *   sensor_msgs/JointState     header{stamp{int32 sec, uint32 nanosec}, string frame_id},
 *                              string[] name, float64[] position, velocity, effort
 *   geometry_msgs/PointStamped header, point{float64 x, y, z}
 *   std_msgs/Float64MultiArray layout{dim[] {string label, uint32 size, uint32 stride},
 *                              uint32 data_offset}, float64[] data
 *   std_msgs/String            string data
 */
#ifndef AMSFE_CDR_H
#define AMSFE_CDR_H

#include <stddef.h>
#include <stdint.h>
#include <string.h>

/* The encapsulation header of little-endian plain CDR. */
static const unsigned char AMSFE_CDR_LE[4] = {0x00, 0x01, 0x00, 0x00};

/* A reader over one serialized message: fails (ok = 0) instead of reading past the end. */
typedef struct {
  const unsigned char *p; /* the payload (after the encapsulation) */
  size_t len, pos;
  int ok;
} cdr_in;

static inline void cdr_in_init(cdr_in *r, const unsigned char *buf, size_t len) {
  r->ok = len >= 4 && buf[0] == 0x00 && buf[1] == 0x01; /* CDR_LE only */
  r->p = buf + 4, r->len = len >= 4 ? len - 4 : 0, r->pos = 0;
}

static inline int cdr_align(cdr_in *r, size_t a) {
  size_t pos = (r->pos + a - 1) / a * a;
  if (!r->ok || pos > r->len) return r->ok = 0;
  r->pos = pos;
  return 1;
}

/* `size` bytes, aligned to `size`, into v (left as it is past the end: r->ok = 0). */
static inline void cdr_get(cdr_in *r, void *v, size_t size) {
  if (!cdr_align(r, size) || r->pos + size > r->len) {
    r->ok = 0;
    return;
  }
  memcpy(v, r->p + r->pos, size);
  r->pos += size;
}

static inline uint32_t cdr_u32(cdr_in *r) {
  uint32_t v = 0;
  cdr_get(r, &v, 4);
  return v;
}

static inline double cdr_f64(cdr_in *r) {
  double v = 0.0;
  cdr_get(r, &v, 8);
  return v;
}

/* A string: its bytes (NUL-terminated inside the buffer) or NULL. */
static inline const char *cdr_string(cdr_in *r) {
  uint32_t n = cdr_u32(r);
  if (!r->ok || n == 0 || r->pos + n > r->len || r->p[r->pos + n - 1] != 0) return r->ok = 0, NULL;
  const char *s = (const char *)(r->p + r->pos);
  r->pos += n;
  return s;
}

/* A header: its stamp [ns]. */
static inline long long cdr_header(cdr_in *r) {
  int32_t sec = (int32_t)cdr_u32(r);
  uint32_t nsec = cdr_u32(r);
  (void)cdr_string(r); /* frame_id */
  return (long long)sec * 1000000000LL + (long long)nsec;
}

/* A float64[]: its length, the values copied to out (at most cap of them; *count gets the
 * message's length, which may exceed cap: the caller refuses it). */
static inline void cdr_doubles(cdr_in *r, double *out, int cap, int *count) {
  uint32_t n = cdr_u32(r);
  *count = (int)n;
  if (!r->ok || n == 0) return;
  if (!cdr_align(r, 8) || r->pos + 8 * (size_t)n > r->len) {
    r->ok = 0;
    return;
  }
  memcpy(out, r->p + r->pos, 8 * (size_t)(n < (uint32_t)cap ? n : (uint32_t)cap));
  r->pos += 8 * (size_t)n;
}

/* A writer into a buffer of fixed capacity (ok = 0 when it would overflow). */
typedef struct {
  unsigned char *p; /* the payload (after the encapsulation) */
  size_t cap, pos;
  int ok;
} cdr_out;

static inline void cdr_out_init(cdr_out *w, unsigned char *buf, size_t cap) {
  memcpy(buf, AMSFE_CDR_LE, 4);
  w->p = buf + 4, w->cap = cap - 4, w->pos = 0, w->ok = cap >= 4;
}

static inline void cdr_put_align(cdr_out *w, size_t a) {
  while (w->ok && w->pos % a) {
    if (w->pos >= w->cap) {
      w->ok = 0;
      return;
    }
    w->p[w->pos++] = 0;
  }
}

static inline void cdr_put(cdr_out *w, const void *v, size_t size, size_t align) {
  cdr_put_align(w, align);
  if (!w->ok || w->pos + size > w->cap) {
    w->ok = 0;
    return;
  }
  memcpy(w->p + w->pos, v, size);
  w->pos += size;
}

static inline void cdr_put_u32(cdr_out *w, uint32_t v) { cdr_put(w, &v, 4, 4); }

static inline void cdr_put_string(cdr_out *w, const char *s) {
  uint32_t n = (uint32_t)strlen(s) + 1;
  cdr_put_u32(w, n);
  cdr_put(w, s, n, 1);
}

/* A float64[] of n values; *at gets the offset of the first value (to refill in place). */
static inline void cdr_put_doubles(cdr_out *w, const double *v, int n, size_t *at) {
  cdr_put_u32(w, (uint32_t)n);
  if (n > 0) cdr_put_align(w, 8);
  if (at) *at = w->pos;
  for (int i = 0; i < n; ++i) cdr_put(w, v ? &v[i] : &(double){0.0}, 8, 8);
}

/* Total bytes written (encapsulation included). */
static inline size_t cdr_out_size(const cdr_out *w) { return w->pos + 4; }

#endif /* AMSFE_CDR_H */
