// AFF parser: one pass over each file's tokens, includes expanded in place.
#include "artrace/io/aff_scene.h"
#include "artrace/io/parse_error.h"
#include "artrace/io/text_file.h"

#include <glm/gtc/matrix_transform.hpp>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <limits>
#include <sstream>

namespace artrace::io {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kMaxIncludeDepth = 32;
constexpr long kMaxCount = 50'000'000;  // larger counts are corrupt files, not scenes
constexpr long kCheckedCount = 65'536;   // larger counts are checked against the file's length first

struct Token {
  std::string_view text;
  int line = 0;
  int col = 0;
};

class Lexer {
 public:
  Lexer(std::string file, std::string content) : file_(std::move(file)), src_(std::move(content)) {}

  const std::string& file() const { return file_; }

  /// Next token, or false at the end of the file.
  bool next(Token& tok) {
    if (has_peek_) {
      has_peek_ = false;
      tok = peeked_;
      return true;
    }
    return scan(tok);
  }
  bool peek(Token& tok) {
    if (!has_peek_) {
      if (!scan(peeked_)) return false;
      has_peek_ = true;
    }
    tok = peeked_;
    return true;
  }
  /// Bytes of the file not read yet (a peeked token counts as unread).
  size_t remaining() const { return src_.size() - pos_ + (has_peek_ ? peeked_.text.size() : 0); }
  /// Where the file ended, for "unexpected end of file" errors.
  Token end_token() const { return Token{{}, line_, col()}; }

 private:
  int col() const { return static_cast<int>(pos_ - line_start_) + 1; }

  bool scan(Token& tok) {
    const size_t n = src_.size();
    for (;;) {
      while (pos_ < n && std::isspace(static_cast<unsigned char>(src_[pos_]))) {
        if (src_[pos_] == '\n') {
          ++line_;
          line_start_ = pos_ + 1;
        }
        ++pos_;
      }
      if (pos_ < n && (src_[pos_] == '#' || src_[pos_] == '%')) {
        while (pos_ < n && src_[pos_] != '\n') ++pos_;
        continue;
      }
      break;
    }
    if (pos_ >= n) return false;
    tok.line = line_;
    tok.col = col();
    const size_t start = pos_;
    if (src_[pos_] == '{' || src_[pos_] == '}') {
      ++pos_;
    } else {
      while (pos_ < n && !std::isspace(static_cast<unsigned char>(src_[pos_])) && src_[pos_] != '{' &&
             src_[pos_] != '}' && src_[pos_] != '#' && src_[pos_] != '%') {
        ++pos_;
      }
    }
    tok.text = std::string_view(src_).substr(start, pos_ - start);
    return true;
  }

  std::string file_;
  std::string src_;
  size_t pos_ = 0;
  size_t line_start_ = 0;
  int line_ = 1;
  bool has_peek_ = false;
  Token peeked_;
};

bool is_number(std::string_view s) {
  if (s.empty()) return false;
  const char c = s[0];
  return std::isdigit(static_cast<unsigned char>(c)) || c == '-' || c == '+' || c == '.';
}

struct Scope {
  glm::dmat4 matrix{1.0};  ///< from this scope's frame to its node's frame
  int node = 0;
  Token open;              ///< the '{' (for unclosed-brace errors)
  std::string file;
};

class Parser {
 public:
  explicit Parser(AffScene& scene) : scene_(scene) {
    scene_.nodes.emplace_back();
    scene_.materials.emplace_back();  // default material for geometry before any f/fm
    scopes_.push_back(Scope{});
  }

  void parse_file(const std::filesystem::path& path, int depth, const Lexer* from, const Token* at) {
    // a file that is still being read, included again, would be followed forever: name the cycle
    std::error_code ec;
    std::filesystem::path key = std::filesystem::weakly_canonical(path, ec);
    if (ec) key = path.lexically_normal();
    for (std::size_t i = 0; i < reading_.size(); ++i) {
      if (reading_[i] != key) continue;
      std::string chain;
      for (std::size_t j = i; j < reading_.size(); ++j) chain += reading_[j].filename().string() + " -> ";
      fail(*from, *at, "include cycle: " + chain + key.filename().string());
    }
    if (depth > kMaxIncludeDepth) fail(*from, *at, "includes nested deeper than 32");
    if (from && !std::filesystem::exists(path)) fail(*from, *at, "cannot open included file '" + path.string() + "'");
    Lexer lex(path.string(), read_text_file(path));
    const std::filesystem::path dir = path.parent_path();
    Token tok;
    reading_.push_back(key);
    while (lex.next(tok)) record(lex, tok, dir, depth);
    reading_.pop_back();
  }

  void finish() {
    if (scopes_.size() > 1) {
      const Scope& s = scopes_.back();
      throw ParseError(s.file, s.open.line, s.open.col, "'{' is never closed");
    }
  }

 private:
  [[noreturn]] static void fail(const Lexer& lex, const Token& tok, const std::string& what) {
    throw ParseError(lex.file(), tok.line, tok.col, what);
  }

  Token expect_token(Lexer& lex, const char* what) {
    Token t;
    if (!lex.next(t)) fail(lex, lex.end_token(), std::string("unexpected end of file, expected ") + what);
    return t;
  }

  Token expect_word(Lexer& lex, std::string_view word) {
    const Token t = expect_token(lex, std::string(word).c_str());
    if (t.text != word) {
      fail(lex, t, "expected '" + std::string(word) + "', got " + quote_token(t.text));
    }
    return t;
  }

  /// A number; finite and within the float range (the scene is kept in floats). `where`, when
  /// given, receives its token.
  double number(Lexer& lex, const char* what, Token* where = nullptr) {
    const Token t = expect_token(lex, what);
    if (where) *where = t;
    std::string_view s = t.text;
    if (!s.empty() && s[0] == '+') s.remove_prefix(1);
    double v = 0.0;
    const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), v);
    if (ec != std::errc() || end != s.data() + s.size()) {
      fail(lex, t, std::string("expected ") + what + ", got " + quote_token(t.text));
    }
    if (!std::isfinite(v)) fail(lex, t, std::string("expected ") + what + ", got the non-finite " + quote_token(t.text));
    if (std::fabs(v) > static_cast<double>(std::numeric_limits<float>::max())) {
      fail(lex, t, std::string("expected ") + what + ", got " + quote_token(t.text) + ", beyond the float range");
    }
    return v;
  }

  /// A count of items of `numbers_each` numbers that follow it. A large one (what it allocates
  /// matters) is refused when the rest of the file is too short to hold its items (a number takes
  /// at least two bytes with its separator), before anything is allocated: a corrupt count in a
  /// short file would otherwise ask for gigabytes. A small one is left to the reading of its
  /// items, whose errors say where the file ends or which token is wrong.
  long count(Lexer& lex, const char* what, long lo, long numbers_each) {
    Token at;
    const long n = integer(lex, what, lo, kMaxCount, &at);
    const long need = n * numbers_each * 2 - 1;
    if (n > kCheckedCount && need > static_cast<long>(lex.remaining())) {
      fail(lex, at, std::string(what) + " " + std::to_string(n) + " needs at least " + std::to_string(need) + " more bytes (" +
                        std::to_string(numbers_each) + " numbers each), but the file has " + std::to_string(lex.remaining()) + " left");
    }
    return n;
  }

  long integer(Lexer& lex, const char* what, long lo, long hi, Token* at = nullptr) {
    const Token t = expect_token(lex, what);
    if (at) *at = t;
    long v = 0;
    const auto [end, ec] = std::from_chars(t.text.data(), t.text.data() + t.text.size(), v);
    if (ec != std::errc() || end != t.text.data() + t.text.size()) {
      fail(lex, t, std::string("expected ") + what + " (an integer), got " + quote_token(t.text));
    }
    if (v < lo || v > hi) {
      fail(lex, t, std::string(what) + " " + std::to_string(v) + " is out of range [" + std::to_string(lo) + ", " +
                       std::to_string(hi) + "]");
    }
    return v;
  }

  glm::dvec3 vec3(Lexer& lex, const char* what) {
    const double x = number(lex, what);
    const double y = number(lex, what);
    const double z = number(lex, what);
    return {x, y, z};
  }

  std::string word(Lexer& lex, const char* what) {
    const Token t = expect_token(lex, what);
    if (t.text == "{" || t.text == "}") fail(lex, t, std::string("expected ") + what + ", got '" + std::string(t.text) + "'");
    return std::string(t.text);
  }

  void open_brace(Lexer& lex, Scope scope) {
    const Token t = expect_token(lex, "'{'");
    if (t.text != "{") fail(lex, t, "expected '{', got " + quote_token(t.text));
    scope.open = t;
    scope.file = lex.file();
    scopes_.push_back(std::move(scope));
  }

  int texture_index(const std::string& name, const std::filesystem::path& dir) {
    const auto it = texture_ids_.find(name);
    if (it != texture_ids_.end()) return it->second;
    std::filesystem::path p = dir.parent_path() / "TextureFiles" / name;
    if (!std::filesystem::exists(p) && std::filesystem::exists(dir / name)) p = dir / name;
    const int id = static_cast<int>(scene_.textures.size());
    scene_.textures.push_back(p);
    texture_ids_.emplace(name, id);
    return id;
  }

  /// Adds one triangle in the current scope's frame to the current node.
  void emit(const glm::dvec3 p[3], const glm::dvec3* n, const glm::dvec2* uv, int texture) {
    const Scope& s = scopes_.back();
    TriangleBatch& b = scene_.nodes[s.node].geometry;
    core::Triangle tri;
    glm::vec3* v[3] = {&tri.v0, &tri.v1, &tri.v2};
    for (int i = 0; i < 3; ++i) *v[i] = glm::vec3(s.matrix * glm::dvec4(p[i], 1.0));
    std::array<glm::vec3, 3> normals;
    if (n) {
      const glm::dmat3 nm = glm::transpose(glm::inverse(glm::dmat3(s.matrix)));
      for (int i = 0; i < 3; ++i) {
        const glm::dvec3 t = nm * n[i];
        const double len = glm::length(t);
        normals[i] = glm::vec3(len > 0.0 ? t / len : t);
      }
    } else {
      glm::vec3 g = tri.geometric_normal();
      const float len = glm::length(g);
      if (len > 0.0f) g /= len;
      normals = {g, g, g};
    }
    std::array<glm::vec2, 3> uvs{};
    if (uv) uvs = {glm::vec2(uv[0]), glm::vec2(uv[1]), glm::vec2(uv[2])};
    b.tris.push_back(tri);
    b.normals.push_back(normals);
    b.uvs.push_back(uvs);
    b.material.push_back(material_);
    b.texture.push_back(texture);
  }

  /// Fan-triangulates a polygon.
  void emit_polygon(const std::vector<glm::dvec3>& p, const std::vector<glm::dvec3>* n,
                    const std::vector<glm::dvec2>* uv, int texture) {
    for (size_t i = 1; i + 1 < p.size(); ++i) {
      const glm::dvec3 tp[3] = {p[0], p[i], p[i + 1]};
      glm::dvec3 tn[3];
      glm::dvec2 tu[3];
      if (n) tn[0] = (*n)[0], tn[1] = (*n)[i], tn[2] = (*n)[i + 1];
      if (uv) tu[0] = (*uv)[0], tu[1] = (*uv)[i], tu[2] = (*uv)[i + 1];
      emit(tp, n ? tn : nullptr, uv ? tu : nullptr, texture);
    }
  }

  void record(Lexer& lex, const Token& tok, const std::filesystem::path& dir, int depth) {
    const std::string_view k = tok.text;
    if (k == "v") return view(lex);
    if (k == "b") return void(scene_.background = glm::vec3(vec3(lex, "a background colour component")));
    if (k == "am") return void(scene_.ambient = glm::vec3(vec3(lex, "an ambient colour component")));
    if (k == "l") return light(lex);
    if (k == "a") return animation_range(lex, tok);
    if (k == "f") return material_f(lex);
    if (k == "fm") return material_fm(lex);
    if (k == "p" || k == "pp") return polygon(lex, k == "pp");
    if (k == "tt" || k == "ttp") return textured_triangle(lex, k == "ttp", dir);
    if (k == "s") return sphere(lex);
    if (k == "c") return cone(lex);
    if (k == "m") return mesh(lex, dir);
    if (k == "tpa") return animated_triangle(lex);
    if (k == "i") return include(lex, dir, depth);
    if (k == "xs") return static_transform(lex);
    if (k == "x") return animated_transform(lex);
    if (k == "k") return keyframes(lex, tok);
    if (k == "}") {
      if (scopes_.size() <= 1) fail(lex, tok, "'}' without a matching '{'");
      scopes_.pop_back();
      return;
    }
    fail(lex, tok, "unknown record " + quote_token(k));
  }

  void view(Lexer& lex) {
    AffView v;
    expect_word(lex, "from");
    v.from = glm::vec3(vec3(lex, "a number after 'from'"));
    expect_word(lex, "at");
    v.at = glm::vec3(vec3(lex, "a number after 'at'"));
    const Token up = expect_word(lex, "up");
    v.up = glm::vec3(vec3(lex, "a number after 'up'"));
    if (!core::Camera::valid_view(v.from, v.at, v.up)) {
      fail(lex, up, "the view needs 'at' apart from 'from' and 'up' not parallel to the view direction");
    }
    expect_word(lex, "angle");
    Token angle;
    v.fov_y_deg = static_cast<float>(number(lex, "the view angle in degrees", &angle));
    if (!core::Camera::valid_fov(v.fov_y_deg)) {
      fail(lex, angle, "the view angle " + quote_token(angle.text) + " is not between 0 and 180 degrees");
    }
    expect_word(lex, "hither");
    v.hither = static_cast<float>(number(lex, "the hither distance"));
    expect_word(lex, "resolution");
    v.width = static_cast<int>(integer(lex, "the image width", 1, 65536));
    v.height = static_cast<int>(integer(lex, "the image height", 1, 65536));
    scene_.view = v;
  }

  void light(Lexer& lex) {
    AffLight l;
    l.position = glm::vec3(vec3(lex, "a light position component"));
    Token t;
    if (lex.peek(t) && is_number(t.text)) l.color = glm::vec3(vec3(lex, "a light colour component"));
    scene_.lights.push_back(l);
  }

  void animation_range(Lexer& lex, const Token& tok) {
    scene_.anim_start = number(lex, "the animation start time");
    scene_.anim_end = number(lex, "the animation end time");
    scene_.anim_frames = static_cast<int>(integer(lex, "the number of frames", 1, 10'000'000));
    if (scene_.anim_end < scene_.anim_start) fail(lex, tok, "animation ends before it starts");
  }

  void material_f(Lexer& lex) {
    const glm::dvec3 c = vec3(lex, "a material colour component");
    const double kd = number(lex, "Kd"), ks = number(lex, "Ks"), shine = number(lex, "the Phong exponent");
    const double t = number(lex, "the transmittance"), ior = number(lex, "the index of refraction");
    AffMaterial m;
    m.diffuse = glm::vec3(kd * c);
    m.specular = glm::vec3(ks * c);
    m.shine = static_cast<float>(shine);
    m.transmittance = static_cast<float>(t);
    m.ior = static_cast<float>(ior);
    add_material(m);
  }

  void material_fm(Lexer& lex) {
    AffMaterial m;
    m.ambient = glm::vec3(vec3(lex, "an ambient colour component"));
    m.diffuse = glm::vec3(vec3(lex, "a diffuse colour component"));
    m.specular = glm::vec3(vec3(lex, "a specular colour component"));
    m.shine = static_cast<float>(number(lex, "the Phong exponent"));
    m.transmittance = static_cast<float>(number(lex, "the transmittance"));
    m.ior = static_cast<float>(number(lex, "the index of refraction"));
    add_material(m);
  }

  void add_material(const AffMaterial& m) {
    material_ = static_cast<uint32_t>(scene_.materials.size());
    scene_.materials.push_back(m);
  }

  void polygon(Lexer& lex, bool with_normals) {
    const long n = count(lex, "the vertex count", 3, with_normals ? 6 : 3);
    std::vector<glm::dvec3> p(n), nrm(with_normals ? n : 0);
    for (long i = 0; i < n; ++i) {
      p[i] = vec3(lex, "a vertex coordinate");
      if (with_normals) nrm[i] = vec3(lex, "a normal component");
    }
    emit_polygon(p, with_normals ? &nrm : nullptr, nullptr, -1);
  }

  void textured_triangle(Lexer& lex, bool with_normals, const std::filesystem::path& dir) {
    const int tex = texture_index(word(lex, "a texture file name"), dir);
    glm::dvec3 p[3], n[3];
    glm::dvec2 uv[3];
    for (int i = 0; i < 3; ++i) {
      p[i] = vec3(lex, "a vertex coordinate");
      if (with_normals) n[i] = vec3(lex, "a normal component");
      const double u = number(lex, "a texture coordinate");
      uv[i] = {u, number(lex, "a texture coordinate")};
    }
    emit(p, with_normals ? n : nullptr, uv, tex);
  }

  void sphere(Lexer& lex) {
    const glm::dvec3 c = vec3(lex, "a sphere centre coordinate");
    const double r = number(lex, "the sphere radius");
    constexpr int kRings = 16, kSegments = 32;
    auto at = [&](int i, int j) {
      const double th = kPi * i / kRings, ph = 2.0 * kPi * j / kSegments;
      return glm::dvec3(std::sin(th) * std::cos(ph), std::cos(th), std::sin(th) * std::sin(ph));
    };
    for (int i = 0; i < kRings; ++i) {
      for (int j = 0; j < kSegments; ++j) {
        const glm::dvec3 n[4] = {at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j)};
        const glm::dvec3 p[4] = {c + r * n[0], c + r * n[1], c + r * n[2], c + r * n[3]};
        const glm::dvec3 p0[3] = {p[0], p[1], p[2]}, n0[3] = {n[0], n[1], n[2]};
        const glm::dvec3 p1[3] = {p[0], p[2], p[3]}, n1[3] = {n[0], n[2], n[3]};
        if (i > 0) emit(p0, n0, nullptr, -1);
        if (i + 1 < kRings) emit(p1, n1, nullptr, -1);
      }
    }
  }

  void cone(Lexer& lex) {
    const glm::dvec3 base = vec3(lex, "a cone base coordinate");
    const double rb = number(lex, "the base radius");
    const glm::dvec3 apex = vec3(lex, "a cone apex coordinate");
    const double ra = number(lex, "the apex radius");
    const glm::dvec3 axis = apex - base;
    if (glm::length(axis) == 0.0) return;
    const glm::dvec3 w = glm::normalize(axis);
    const glm::dvec3 helper = std::fabs(w.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0);
    const glm::dvec3 u = glm::normalize(glm::cross(w, helper)), v = glm::cross(w, u);
    constexpr int kSegments = 32;
    for (int j = 0; j < kSegments; ++j) {
      const double a0 = 2.0 * kPi * j / kSegments, a1 = 2.0 * kPi * (j + 1) / kSegments;
      const glm::dvec3 d0 = std::cos(a0) * u + std::sin(a0) * v, d1 = std::cos(a1) * u + std::sin(a1) * v;
      const glm::dvec3 p[4] = {base + rb * d0, base + rb * d1, apex + ra * d1, apex + ra * d0};
      const glm::dvec3 t0[3] = {p[0], p[1], p[2]}, n0[3] = {d0, d1, d1};
      const glm::dvec3 t1[3] = {p[0], p[2], p[3]}, n1[3] = {d0, d1, d0};
      emit(t0, n0, nullptr, -1);
      emit(t1, n1, nullptr, -1);
    }
  }

  void mesh(Lexer& lex, const std::filesystem::path& dir) {
    expect_word(lex, "vertices");
    const long nv = count(lex, "the vertex count", 0, 3);
    std::vector<glm::dvec3> pos(nv);
    for (auto& p : pos) p = vec3(lex, "a vertex coordinate");
    std::vector<glm::dvec3> nrm;
    std::vector<glm::dvec2> uvs;
    int tex = -1;
    Token t = expect_token(lex, "'normals', 'texturecoords' or 'triangles'");
    if (t.text == "normals") {
      nrm.resize(count(lex, "the normal count", 0, 3));
      for (auto& n : nrm) n = vec3(lex, "a normal component");
      t = expect_token(lex, "'texturecoords' or 'triangles'");
    }
    if (t.text == "texturecoords") {
      uvs.resize(count(lex, "the texture coordinate count", 0, 2));
      tex = texture_index(word(lex, "a texture file name"), dir);
      for (auto& uv : uvs) {
        const double u = number(lex, "a texture coordinate");
        uv = {u, number(lex, "a texture coordinate")};
      }
      t = expect_token(lex, "'triangles'");
    }
    if (t.text != "triangles") fail(lex, t, "expected 'triangles' in mesh, got " + quote_token(t.text));
    const long nt = count(lex, "the triangle count", 0, 3);
    for (long i = 0; i < nt; ++i) {
      glm::dvec3 p[3], n[3];
      glm::dvec2 uv[3];
      for (int c = 0; c < 3; ++c) p[c] = pos[integer(lex, "a vertex index", 0, nv - 1)];
      if (!nrm.empty()) {
        for (int c = 0; c < 3; ++c) n[c] = nrm[integer(lex, "a normal index", 0, static_cast<long>(nrm.size()) - 1)];
      }
      if (!uvs.empty()) {
        for (int c = 0; c < 3; ++c) uv[c] = uvs[integer(lex, "a texture coordinate index", 0, static_cast<long>(uvs.size()) - 1)];
      }
      emit(p, nrm.empty() ? nullptr : n, uvs.empty() ? nullptr : uv, tex);
    }
  }

  void animated_triangle(Lexer& lex) {
    const long n = count(lex, "the key count", 1, 19);
    AffAnimatedTriangle a;
    a.node = scopes_.back().node;
    a.material = material_;
    const glm::dmat4& m = scopes_.back().matrix;
    for (long i = 0; i < n; ++i) {
      a.times.push_back(number(lex, "a key time"));
      glm::dvec3 p[3];
      for (int c = 0; c < 3; ++c) {
        p[c] = vec3(lex, "a vertex coordinate");
        vec3(lex, "a normal component");
      }
      a.keys.push_back({glm::vec3(m * glm::dvec4(p[0], 1)), glm::vec3(m * glm::dvec4(p[1], 1)),
                        glm::vec3(m * glm::dvec4(p[2], 1))});
    }
    scene_.animated_triangles.push_back(std::move(a));
  }

  void include(Lexer& lex, const std::filesystem::path& dir, int depth) {
    integer(lex, "the detail level", -1000000, 1000000);
    const Token name = expect_token(lex, "an include file name");
    parse_file(dir / std::string(name.text), depth + 1, &lex, &name);
  }

  void static_transform(Lexer& lex) {
    const glm::dvec3 s = vec3(lex, "a scale factor");
    const glm::dvec3 axis = vec3(lex, "a rotation axis component");
    const double angle = number(lex, "the rotation angle in degrees");
    const glm::dvec3 t = vec3(lex, "a translation component");
    glm::dmat4 m = glm::translate(glm::dmat4(1.0), t);
    if (glm::length(axis) > 0.0) m = glm::rotate(m, glm::radians(angle), glm::normalize(axis));
    m = glm::scale(m, s);
    Scope scope = scopes_.back();
    scope.matrix = scope.matrix * m;
    open_brace(lex, scope);
  }

  void animated_transform(Lexer& lex) {
    AffNode node;
    node.parent = scopes_.back().node;
    node.offset = scopes_.back().matrix;
    node.animation = word(lex, "an animation name");
    const int id = static_cast<int>(scene_.nodes.size());
    scene_.nodes.push_back(std::move(node));
    Scope scope;
    scope.node = id;
    open_brace(lex, scope);
  }

  std::vector<TcbKey> track(Lexer& lex, bool rotation) {
    const long n = count(lex, "the key count", 1, 7);
    std::vector<TcbKey> keys(n);
    for (auto& k : keys) {
      k.time = number(lex, "a key time");
      k.value = vec3(lex, "a key value");
      if (rotation) k.angle_deg = number(lex, "a rotation angle in degrees");
      k.tension = number(lex, "the tension");
      k.continuity = number(lex, "the continuity");
      k.bias = number(lex, "the bias");
    }
    // Key times are not required to increase: the robots' gun_rot tracks restart at t = 42 after
    // reaching 48. Evaluation takes the first segment that contains t (keyframe_animation.cpp).
    return keys;
  }

  void keyframes(Lexer& lex, const Token& tok) {
    KeyframeAnimation anim;
    anim.name = word(lex, "an animation name");
    const Token open = expect_token(lex, "'{'");
    if (open.text != "{") fail(lex, open, "expected '{' after 'k " + anim.name + "'");
    for (;;) {
      const Token t = expect_token(lex, "'transl', 'rot', 'scale' or '}'");
      if (t.text == "}") break;
      if (t.text == "transl") anim.translation = TcbTrack(track(lex, false));
      else if (t.text == "rot") anim.rotation = TcbRotationTrack(track(lex, true));
      else if (t.text == "scale") anim.scale = TcbTrack(track(lex, false));
      else fail(lex, t, "expected 'transl', 'rot', 'scale' or '}' in animation '" + anim.name + "', got " + quote_token(t.text));
    }
    // A file included twice (the kitchen's wheels are) defines its animations again: the same
    // record is fine, a different one with the same name is an error.
    const std::string origin = lex.file() + ":" + std::to_string(tok.line);
    const auto [it, added] = animation_origin_.emplace(anim.name, origin);
    if (!added) {
      if (it->second == origin) return;
      fail(lex, tok, "animation '" + anim.name + "' is already defined at " + it->second);
    }
    scene_.animations.emplace(anim.name, std::move(anim));
  }

  AffScene& scene_;
  std::vector<Scope> scopes_;
  std::vector<std::filesystem::path> reading_;  ///< the files being read, outermost first
  uint32_t material_ = 0;
  std::map<std::string, int> texture_ids_;
  std::map<std::string, std::string> animation_origin_;
};

}  // namespace

AffScene load_aff(const std::filesystem::path& file) {
  AffScene scene;
  scene.file = file;
  Parser parser(scene);
  parser.parse_file(file, 0, nullptr, nullptr);
  parser.finish();
  return scene;
}

double AffScene::frame_time(int frame) const {
  if (anim_frames <= 1) return anim_start;
  return anim_start + frame * (anim_end - anim_start) / (anim_frames - 1);
}

glm::dmat4 AffScene::node_transform(int node, double t) const {
  glm::dmat4 m(1.0);
  for (int n = node; n > 0; n = nodes[n].parent) {
    const auto it = animations.find(nodes[n].animation);
    const glm::dmat4 local = nodes[n].offset * (it == animations.end() ? glm::dmat4(1.0) : it->second.transform(t));
    m = local * m;
  }
  return m;
}

std::vector<core::Triangle> AffScene::triangles_at(double t) const {
  std::vector<core::Triangle> out;
  out.reserve(triangle_count());
  for (size_t n = 0; n < nodes.size(); ++n) {
    const TriangleBatch& b = nodes[n].geometry;
    if (n == 0) {
      out.insert(out.end(), b.tris.begin(), b.tris.end());
      continue;
    }
    const glm::dmat4 m = node_transform(static_cast<int>(n), t);
    for (const core::Triangle& tri : b.tris) {
      out.push_back({glm::vec3(m * glm::dvec4(tri.v0, 1.0)), glm::vec3(m * glm::dvec4(tri.v1, 1.0)),
                     glm::vec3(m * glm::dvec4(tri.v2, 1.0))});
    }
  }
  for (const AffAnimatedTriangle& a : animated_triangles) {
    size_t k = 0;
    while (k + 1 < a.times.size() && a.times[k + 1] <= t) ++k;
    core::Triangle tri = a.keys[k];
    if (k + 1 < a.times.size() && t > a.times[k]) {
      const float s = static_cast<float>((t - a.times[k]) / (a.times[k + 1] - a.times[k]));
      const core::Triangle& b = a.keys[k + 1];
      tri = {glm::mix(tri.v0, b.v0, s), glm::mix(tri.v1, b.v1, s), glm::mix(tri.v2, b.v2, s)};
    }
    const glm::dmat4 m = node_transform(a.node, t);
    out.push_back({glm::vec3(m * glm::dvec4(tri.v0, 1.0)), glm::vec3(m * glm::dvec4(tri.v1, 1.0)),
                   glm::vec3(m * glm::dvec4(tri.v2, 1.0))});
  }
  return out;
}

size_t AffScene::triangle_count() const {
  size_t n = animated_triangles.size();
  for (const AffNode& node : nodes) n += node.geometry.size();
  return n;
}

size_t AffScene::static_triangle_count() const { return nodes.empty() ? 0 : nodes[0].geometry.size(); }

float AffScene::transmittance(uint32_t material) const {
  return material < materials.size() ? std::clamp(materials[material].transmittance, 0.0f, 1.0f) : 0.0f;
}

bool AffScene::deforming_transmissive() const {
  return std::any_of(animated_triangles.begin(), animated_triangles.end(),
                     [&](const AffAnimatedTriangle& t) { return transmittance(t.material) > 0.0f; });
}

core::Camera AffScene::camera_at(double t, int width, int height) const {
  const float fov = view ? view->fov_y_deg : 45.0f;
  const auto it = animations.find("camera");
  if (it != animations.end()) {
    const KeyframeAnimation& cam = it->second;
    const glm::dvec3 pos = cam.translation.evaluate(t);
    const glm::dmat3 rot = glm::mat3_cast(cam.rotation.evaluate(t));
    return core::Camera::from_gl_pose(glm::vec3(pos), glm::mat3(rot), fov, width, height);
  }
  if (!view) throw std::runtime_error(file.string() + ": the scene has neither a 'v' view nor a camera animation");
  return core::Camera::look_at(view->from, view->at, view->up, fov, width, height);
}

}  // namespace artrace::io
