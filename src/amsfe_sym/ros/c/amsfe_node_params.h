/* amsfe_node_params.h: the parameter file of amsfe_node (written by amsfe_sym.ros.cnode;
 * one record a line, "<key> <value> ...", whitespace-separated; keys and their values in
 * cnode.py's write_params).  The whole file is read once at start; a key missing, repeated,
 * with the wrong count of values or a value that does not parse stops the node with one
 * line "PARAMS: <key>: expected ..., found ..." and exit status 2 (bad input).  Nothing here
 * runs after start. */
#ifndef AMSFE_NODE_PARAMS_H
#define AMSFE_NODE_PARAMS_H

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define PF_MAX_TOKENS 64 /* integers or strings of one record (joint names) */

typedef struct {
  const char *path;
  char *text;    /* the file, its tokens NUL-terminated in place */
  char **tok;    /* every token, line after line */
  int *first;    /* [lines + 1]: index in tok of each line's first token (its key) */
  int lines;
} params_file;

static void pf_fail(const params_file *pf, const char *key, const char *fmt, const char *found)
    __attribute__((noreturn));
static void pf_fail(const params_file *pf, const char *key, const char *fmt, const char *found) {
  fprintf(stderr, "error: %s: %s: expected %s, found %s. Fix: write it with amsfe node "
          "(amsfe_sym.ros.cnode.write_params)\n", pf->path, key, fmt, found);
  exit(2);
}

/* Read the file and cut it into lines of tokens. */
static void pf_open(params_file *pf, const char *path) {
  memset(pf, 0, sizeof(*pf));
  pf->path = path;
  FILE *f = fopen(path, "rb");
  if (!f) pf_fail(pf, "file", "a readable parameter file", strerror(errno));
  fseek(f, 0, SEEK_END);
  long size = ftell(f);
  fseek(f, 0, SEEK_SET);
  pf->text = malloc((size_t)size + 1);
  if (!pf->text || fread(pf->text, 1, (size_t)size, f) != (size_t)size)
    pf_fail(pf, "file", "its bytes", "a read error");
  fclose(f);
  pf->text[size] = 0;
  size_t ntok = 0, nline = 0;
  for (long i = 0; i < size; ++i) ntok += pf->text[i] != ' ' && pf->text[i] != '\n' &&
                                          (i == 0 || pf->text[i - 1] == ' ' ||
                                           pf->text[i - 1] == '\n');
  for (long i = 0; i < size; ++i) nline += pf->text[i] == '\n';
  pf->tok = malloc(sizeof(char *) * (ntok + 1));
  pf->first = malloc(sizeof(int) * (nline + 2));
  int t = 0;
  char *s = pf->text;
  while (*s) {
    char *eol = strchr(s, '\n');
    if (!eol) eol = s + strlen(s);
    int at = t;
    for (char *c = s; c < eol;) {
      while (c < eol && *c == ' ') *c++ = 0;
      if (c >= eol) break;
      pf->tok[t++] = c;
      while (c < eol && *c != ' ') ++c;
    }
    if (t > at) pf->first[pf->lines++] = at;
    int last = !*eol;
    *eol = 0;
    if (last) break;
    s = eol + 1;
  }
  pf->first[pf->lines] = t;
}

/* The tokens of record `key` (after the key) in toks (at most cap), their count returned;
 * exactly one line with that key unless `optional` (then no line: -1). */
static int pf_tokens(const params_file *pf, const char *key, const char **toks, int cap,
                     int optional) {
  int found = -1;
  for (int i = 0; i < pf->lines; ++i) {
    if (strcmp(pf->tok[pf->first[i]], key) != 0) continue;
    if (found >= 0) pf_fail(pf, key, "one line", "a second");
    found = i;
  }
  if (found < 0) {
    if (optional) return -1;
    pf_fail(pf, key, "a line", "none");
  }
  int n = pf->first[found + 1] - pf->first[found] - 1;
  for (int i = 0; i < n && i < cap; ++i) toks[i] = pf->tok[pf->first[found] + 1 + i];
  return n;
}

static double pf_parse_double(const params_file *pf, const char *key, const char *tok) {
  char *e;
  double v = strtod(tok, &e);
  if (e == tok || *e) pf_fail(pf, key, "a number", tok);
  return v;
}

static long long pf_parse_long(const params_file *pf, const char *key, const char *tok) {
  char *e;
  errno = 0;
  long long v = strtoll(tok, &e, 10);
  if (e == tok || *e || errno) pf_fail(pf, key, "an integer", tok);
  return v;
}

/* Exactly `count` numbers of record key into out. */
static void pf_doubles(const params_file *pf, const char *key, double *out, int count) {
  const char **toks = malloc(sizeof(char *) * (size_t)(count > 0 ? count : 1));
  int n = pf_tokens(pf, key, toks, count, 0);
  if (n != count) {
    char found[32];
    snprintf(found, sizeof found, "%d values", n);
    char want[32];
    snprintf(want, sizeof want, "%d values", count);
    pf_fail(pf, key, want, found);
  }
  for (int i = 0; i < count; ++i) out[i] = pf_parse_double(pf, key, toks[i]);
  free(toks);
}

static double pf_double(const params_file *pf, const char *key) {
  double v;
  pf_doubles(pf, key, &v, 1);
  return v;
}

static long long pf_long(const params_file *pf, const char *key) {
  const char *tok;
  if (pf_tokens(pf, key, &tok, 1, 0) != 1) pf_fail(pf, key, "one integer", "another count");
  return pf_parse_long(pf, key, tok);
}

/* Exactly `count` integers. */
static void pf_ints(const params_file *pf, const char *key, int *out, int count) {
  const char *toks[PF_MAX_TOKENS];
  if (count > PF_MAX_TOKENS || pf_tokens(pf, key, toks, count, 0) != count)
    pf_fail(pf, key, "its integers", "another count");
  for (int i = 0; i < count; ++i) out[i] = (int)pf_parse_long(pf, key, toks[i]);
}

/* One string value (a topic name). */
static const char *pf_string(const params_file *pf, const char *key) {
  const char *tok;
  if (pf_tokens(pf, key, &tok, 1, 0) != 1) pf_fail(pf, key, "one value", "another count");
  return tok;
}

#endif /* AMSFE_NODE_PARAMS_H */
