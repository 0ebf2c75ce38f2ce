#include "artrace/io/gltf_model.h"
#include "artrace/io/file_name.h"
#include "artrace/io/parse_error.h"
#include "cv_convert.h"

#include <tiny_gltf.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/type_ptr.hpp>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <set>
#include <sstream>

namespace artrace::io {
namespace {

/// The extensions this reader implements (others, when required, make the file unreadable).
const std::set<std::string> kSupported = {"KHR_mesh_quantization", "KHR_texture_transform", "KHR_materials_emissive_strength",
                                          "KHR_materials_transmission", "KHR_materials_ior"};

/// tinygltf's image hook: PNG and JPEG (and what else OpenCV reads) to 8-bit RGBA.
bool decode_image(tinygltf::Image* image, const int index, std::string* err, std::string*, int, int, const unsigned char* bytes,
                  int size, void* deferred) {
  // an image in a bufferView: tinygltf hands over the view's declared range without checking it
  // against its buffer, so it is decoded after loading, once the range is checked (load_gltf)
  if (deferred && image->bufferView >= 0) return true;
  const auto fail = [&](const std::string& what) {
    if (err) *err += "image " + std::to_string(index) + " (" + (image->name.empty() ? image->uri : image->name) + ") " + what + "\n";
    return false;
  };
  // glTF images are PNG or JPEG (WebP with EXT_texture_webp); their headers are checked before
  // OpenCV allocates for what they declare
  if (size <= 0 || !declared_image_size(bytes, static_cast<size_t>(size))) return fail("is not a PNG, JPEG or WebP image");
  if (const std::string bad = image_header_error(bytes, static_cast<size_t>(size)); !bad.empty()) return fail(bad);
  const cv::Mat buf(1, size, CV_8UC1, const_cast<unsigned char*>(bytes));
  cv::Mat m = cv::imdecode(buf, cv::IMREAD_UNCHANGED);
  if (m.empty()) return fail("cannot be decoded (its header is sound, its data is not)");
  if (m.depth() == CV_16U) m.convertTo(m, CV_8U, 1.0 / 257.0);
  if (m.depth() != CV_8U) m.convertTo(m, CV_8U);
  cv::Mat rgba;
  switch (m.channels()) {
    case 1: cv::cvtColor(m, rgba, cv::COLOR_GRAY2RGBA); break;
    case 3: cv::cvtColor(m, rgba, cv::COLOR_BGR2RGBA); break;
    case 4: cv::cvtColor(m, rgba, cv::COLOR_BGRA2RGBA); break;
    default:
      if (err) *err += "image " + std::to_string(index) + " has " + std::to_string(m.channels()) + " channels\n";
      return false;
  }
  image->width = rgba.cols;
  image->height = rgba.rows;
  image->component = 4;
  image->bits = 8;
  image->pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
  image->image.assign(rgba.data, rgba.data + rgba.total() * 4);
  return true;
}

/// Accessor component `q` of type `ctype` as a float (normalised integers to [0, 1] or [-1, 1]).
float component(const unsigned char* q, int ctype, bool normalized) {
  switch (ctype) {
    case TINYGLTF_COMPONENT_TYPE_FLOAT: { float f; std::memcpy(&f, q, 4); return f; }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return *q / (normalized ? 255.0f : 1.0f);
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: { uint16_t s; std::memcpy(&s, q, 2); return s / (normalized ? 65535.0f : 1.0f); }
    case TINYGLTF_COMPONENT_TYPE_SHORT: { int16_t s; std::memcpy(&s, q, 2); return normalized ? std::fmax(s / 32767.0f, -1.0f) : s; }
    case TINYGLTF_COMPONENT_TYPE_BYTE: { int8_t s; std::memcpy(&s, q, 1); return normalized ? std::fmax(s / 127.0f, -1.0f) : s; }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: { uint32_t s; std::memcpy(&s, q, 4); return static_cast<float>(s); }
    default: return std::numeric_limits<float>::quiet_NaN();
  }
}

/// Whether `count` elements of `elem` bytes, `stride` apart (stride >= elem > 0), from `offset`
/// into bufferView `v` lie inside both the view and `held`, the size of its buffer; nothing here
/// can wrap around, whatever the file declares.
bool view_holds(const tinygltf::BufferView& v, size_t held, size_t offset, size_t count, size_t elem, size_t stride) {
  if (v.byteOffset > held || offset > held - v.byteOffset || offset > v.byteLength) return false;
  if (count == 0) return true;
  const size_t room = std::min(held - v.byteOffset - offset, v.byteLength - offset);
  return elem <= room && count - 1 <= (room - elem) / stride;
}

class Reader {
 public:
  Reader(const tinygltf::Model& m, const std::string& file) : m_(m), file_(file) {
    // An accessor without a bufferView is zeros (with sparse values, perhaps): nothing in the file
    // backs its count, which alone would decide an allocation (fuzz_gltf: a 500-byte file declaring
    // 100 million positions asked for 1.2 GB). It may have as many elements as the largest accessor
    // whose elements the file does hold (a sparse morph target has its mesh's vertex count), and
    // at least kUnbackedElements.
    for (const tinygltf::Accessor& a : m_.accessors) {
      if (a.bufferView < 0 || a.bufferView >= static_cast<int>(m_.bufferViews.size())) continue;
      const tinygltf::BufferView& v = m_.bufferViews[static_cast<size_t>(a.bufferView)];
      if (v.buffer < 0 || v.buffer >= static_cast<int>(m_.buffers.size())) continue;
      const size_t elem = element_bytes(a);
      if (elem > 0 && view_holds(v, m_.buffers[static_cast<size_t>(v.buffer)].data.size(), a.byteOffset, a.count, elem, stride_of(v, elem))) {
        unbacked_limit_ = std::max(unbacked_limit_, a.count);
      }
    }
  }

  /// An accessor element's bytes; 0 for an unknown component type or element type.
  static size_t element_bytes(const tinygltf::Accessor& a) {
    const int csize = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(a.componentType));
    const int n = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(a.type));
    return csize > 0 && n > 0 ? static_cast<size_t>(csize) * static_cast<size_t>(n) : 0;
  }
  static size_t stride_of(const tinygltf::BufferView& v, size_t elem) { return v.byteStride ? v.byteStride : elem; }

  [[noreturn]] void fail(const std::string& what) const { throw ParseError(file_, 0, 0, what); }

  /// The bytes of a bufferView from `offset` for `count` elements of `elem` bytes at `stride`,
  /// checked to lie inside the buffer.
  const unsigned char* span(int view, size_t offset, size_t count, size_t elem, size_t stride, const std::string& what) const {
    if (view < 0 || view >= static_cast<int>(m_.bufferViews.size())) fail(what + " names bufferView " + std::to_string(view) + ", which does not exist");
    const tinygltf::BufferView& v = m_.bufferViews[static_cast<size_t>(view)];
    if (v.buffer < 0 || v.buffer >= static_cast<int>(m_.buffers.size())) fail(what + ": its bufferView names a buffer that does not exist");
    const tinygltf::Buffer& b = m_.buffers[static_cast<size_t>(v.buffer)];
    if (!view_holds(v, b.data.size(), offset, count, elem, stride)) fail(what + " runs past the end of its buffer");
    return b.data.data() + v.byteOffset + offset;
  }

  /// An accessor's data, checked before anything is allocated for it, and its elements' stride:
  /// the bytes in its bufferView, or null for one without (zeros, perhaps with sparse values),
  /// which may have at most unbacked_limit_ elements.
  const unsigned char* data_of(const tinygltf::Accessor& a, size_t elem, size_t& stride, const std::string& acc) const {
    stride = elem;
    if (a.bufferView < 0) {
      if (a.count > unbacked_limit_) {
        fail(acc + " declares " + std::to_string(a.count) + " elements and no bufferView to hold them (at most " +
             std::to_string(unbacked_limit_) + ", the most any accessor with data in this file has, or " + std::to_string(kUnbackedElements) + ")");
      }
      return nullptr;
    }
    if (a.bufferView < static_cast<int>(m_.bufferViews.size())) stride = stride_of(m_.bufferViews[static_cast<size_t>(a.bufferView)], elem);
    return span(a.bufferView, a.byteOffset, a.count, elem, stride, acc);
  }

  /// Accessor `index` as `comps` floats per element (normalised integers converted), with its
  /// sparse substitutes applied. Non-finite floats are an error.
  std::vector<float> floats(int index, int comps, const std::string& what) const {
    const std::string acc = what + " (accessor " + std::to_string(index) + ")";
    if (index < 0 || index >= static_cast<int>(m_.accessors.size())) fail(what + " names accessor " + std::to_string(index) + ", which does not exist");
    const tinygltf::Accessor& a = m_.accessors[static_cast<size_t>(index)];
    const int n = tinygltf::GetNumComponentsInType(static_cast<uint32_t>(a.type));
    if (n != comps) fail(acc + " has " + std::to_string(n) + " components, expected " + std::to_string(comps));
    const int csize = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(a.componentType));
    if (csize <= 0) fail(acc + ": unsupported component type " + std::to_string(a.componentType));
    if (a.count > (1u << 28)) fail(acc + ": " + std::to_string(a.count) + " elements");
    const size_t elem = static_cast<size_t>(csize) * n;
    size_t stride = elem;
    const unsigned char* data = data_of(a, elem, stride, acc);
    std::vector<float> out(a.count * static_cast<size_t>(n), 0.0f);
    auto read_into = [&](const unsigned char* p, size_t stride, size_t count, const std::vector<size_t>* dst) {
      for (size_t i = 0; i < count; ++i) {
        const size_t at = dst ? (*dst)[i] : i;
        for (int c = 0; c < n; ++c) {
          const float f = component(p + i * stride + static_cast<size_t>(c) * csize, a.componentType, a.normalized);
          if (!std::isfinite(f)) fail(acc + " holds a non-finite float (element " + std::to_string(at) + ")");
          out[at * n + c] = f;
        }
      }
    };
    if (data) read_into(data, stride, a.count, nullptr);
    if (a.sparse.isSparse) {
      const auto& sp = a.sparse;
      if (sp.count < 0 || static_cast<size_t>(sp.count) > a.count) fail(acc + ": sparse count " + std::to_string(sp.count) + " out of range");
      const int isize = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(sp.indices.componentType));
      if (isize != 1 && isize != 2 && isize != 4) fail(acc + ": sparse indices of an unsupported component type");
      const unsigned char* ip = span(sp.indices.bufferView, static_cast<size_t>(sp.indices.byteOffset), static_cast<size_t>(sp.count),
                                     static_cast<size_t>(isize), static_cast<size_t>(isize), acc + " sparse indices");
      std::vector<size_t> where(static_cast<size_t>(sp.count));
      for (size_t i = 0; i < where.size(); ++i) {
        uint32_t k = 0;
        std::memcpy(&k, ip + i * isize, static_cast<size_t>(isize));
        if (k >= a.count) fail(acc + ": sparse index " + std::to_string(k) + " past its " + std::to_string(a.count) + " elements");
        where[i] = k;
      }
      read_into(span(sp.values.bufferView, static_cast<size_t>(sp.values.byteOffset), where.size(), elem, elem, acc + " sparse values"), elem,
                where.size(), &where);
    }
    return out;
  }

  std::vector<uint32_t> indices(int index, const std::string& what) const {
    const std::string acc = what + " (accessor " + std::to_string(index) + ")";
    if (index < 0 || index >= static_cast<int>(m_.accessors.size())) fail(what + " names accessor " + std::to_string(index) + ", which does not exist");
    const tinygltf::Accessor& a = m_.accessors[static_cast<size_t>(index)];
    const int csize = tinygltf::GetComponentSizeInBytes(static_cast<uint32_t>(a.componentType));
    if (a.type != TINYGLTF_TYPE_SCALAR || (a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE &&
                                           a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
                                           a.componentType != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)) {
      fail(acc + ": indices must be unsigned 8, 16 or 32-bit scalars");
    }
    if (a.count > (1u << 28)) fail(acc + ": " + std::to_string(a.count) + " indices");
    size_t stride = static_cast<size_t>(csize);
    const unsigned char* p = data_of(a, static_cast<size_t>(csize), stride, acc);
    std::vector<uint32_t> out(a.count, 0);
    if (p) {
      for (size_t i = 0; i < a.count; ++i) {
        uint32_t k = 0;
        std::memcpy(&k, p + i * stride, static_cast<size_t>(csize));
        out[i] = k;
      }
    }
    if (a.sparse.isSparse) {
      // rare for indices, but legal: the same substitution as for floats
      const std::vector<float> f = floats(index, 1, what);
      for (size_t i = 0; i < out.size(); ++i) out[i] = static_cast<uint32_t>(f[i]);
    }
    return out;
  }

 private:
  static constexpr size_t kUnbackedElements = 65536;
  const tinygltf::Model& m_;
  std::string file_;
  size_t unbacked_limit_ = kUnbackedElements;
};

/// A number of the glTF JSON as a float; one beyond the float range (or not finite) is an error.
float to_float(double v, const std::string& file, const std::string& what) {
  if (!(std::fabs(v) <= static_cast<double>(std::numeric_limits<float>::max()))) {
    std::ostringstream m;
    m << what << " is " << v << ", beyond the float range";
    throw ParseError(file, 0, 0, m.str());
  }
  return static_cast<float>(v);
}

/// `values` (3 or 4 of them, as the glTF JSON holds them) as floats, each checked by to_float.
template <class Vec>
Vec to_floats(const std::vector<double>& values, const std::string& file, const std::string& what) {
  Vec out;
  for (int k = 0; k < Vec::length(); ++k) out[k] = to_float(values[static_cast<size_t>(k)], file, what);
  return out;
}

// tinygltf's file access for external images and buffers (uris naming files), narrowed to what a
// model can mean. Its own looks for a uri beside the model and then in the current folder, so a
// model missing a texture silently took a file of that name from wherever it was run; and it reads
// a folder as a file whose size, found by seeking to its end, is 2^63 - 1 bytes, which it then
// allocates (fuzz_gltf: a uri "data" run from the project's folder). Here only regular files
// beside the model (or under the folder the uri leads to from there) exist.

/// The folder tinygltf joins a model's uris to: the model's path up to its last separator.
std::string base_folder(const std::string& model) {
  const size_t at = model.find_last_of("/\\");
  return at == std::string::npos ? std::string() : model.substr(0, at);
}

/// `user` is the model's base_folder; tinygltf asks for the uri joined to it, then to ".".
bool file_exists(const std::string& path, void* user) {
  const std::string& base = *static_cast<const std::string*>(user);
  if (!base.empty() && path.compare(0, base.size() + 1, base + "/") != 0) return false;  // not from the model's folder
  std::error_code ec;
  return std::filesystem::is_regular_file(path, ec);
}

bool read_file(std::vector<unsigned char>* out, std::string* err, const std::string& path, void*) {
  std::error_code ec;
  const bool regular = std::filesystem::is_regular_file(path, ec);
  const uintmax_t size = regular ? std::filesystem::file_size(path, ec) : 0;
  std::ifstream f(path, std::ios::binary);
  if (!regular || ec || !f) {
    if (err) *err += path + ": cannot read it as a file\n";
    return false;
  }
  if (size == 0) {  // tinygltf's own reader refuses it too; its parsers do not expect no bytes
    if (err) *err += path + ": the file is empty\n";
    return false;
  }
  out->resize(static_cast<size_t>(size));
  if (!f.read(reinterpret_cast<char*>(out->data()), static_cast<std::streamsize>(size))) {
    if (err) *err += path + ": cannot read its " + std::to_string(size) + " bytes\n";
    return false;
  }
  return true;
}

ar::Wrap wrap_of(int w) {
  return w == TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE ? ar::Wrap::kClampToEdge
         : w == TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT ? ar::Wrap::kMirroredRepeat
                                                       : ar::Wrap::kRepeat;
}

}  // namespace

GltfModel load_gltf(const std::filesystem::path& path) {
  tinygltf::TinyGLTF loader;
  int deferred = 1;
  loader.SetImageLoader(decode_image, &deferred);
  tinygltf::Model m;
  std::string err, warn;
  const std::string file = path.string();
  std::string base = base_folder(file);
  loader.SetFsCallbacks({&file_exists, &tinygltf::ExpandFilePath, &read_file, &tinygltf::WriteWholeFile, &base});
  if (!std::filesystem::exists(path)) throw ParseError(file, 0, 0, "no such file");
  const bool ok = lower_extension(path) == ".glb" ? loader.LoadBinaryFromFile(&m, &err, &warn, file)
                                             : loader.LoadASCIIFromFile(&m, &err, &warn, file);
  if (!ok) throw ParseError(file, 0, 0, "not a readable glTF 2.0 file: " + (err.empty() ? warn : err));
  // the images in bufferViews, their ranges checked against the buffers that hold them
  for (size_t i = 0; i < m.images.size(); ++i) {
    tinygltf::Image& img = m.images[i];
    if (img.bufferView < 0) continue;
    const tinygltf::BufferView& v = m.bufferViews.at(static_cast<size_t>(img.bufferView));
    const size_t held = m.buffers.at(static_cast<size_t>(v.buffer)).data.size();
    if (!view_holds(v, held, 0, v.byteLength, 1, 1) || v.byteLength > static_cast<size_t>(std::numeric_limits<int>::max())) {
      throw ParseError(file, 0, 0, "image " + std::to_string(i) + ": its bufferView " + std::to_string(img.bufferView) + " (bytes " +
                                       std::to_string(v.byteOffset) + " + " + std::to_string(v.byteLength) + ") runs past its buffer's " +
                                       std::to_string(held) + " bytes");
    }
    std::string image_err;
    if (!decode_image(&img, static_cast<int>(i), &image_err, nullptr, 0, 0, m.buffers[static_cast<size_t>(v.buffer)].data.data() + v.byteOffset,
                      static_cast<int>(v.byteLength), nullptr)) {
      throw ParseError(file, 0, 0, "not a readable glTF 2.0 file: " + image_err);
    }
  }
  const Reader r(m, file);
  GltfModel out;
  out.file = path;
  out.extensions_used = m.extensionsUsed;
  out.extensions_required = m.extensionsRequired;
  for (const std::string& e : m.extensionsRequired) {
    if (!kSupported.count(e)) throw ParseError(file, 0, 0, "requires extension " + e + ", which this reader does not support");
  }
  {
    std::string ignored;
    for (const std::string& e : m.extensionsUsed) {
      if (!kSupported.count(e)) ignored += (ignored.empty() ? "" : ", ") + e;
    }
    if (!ignored.empty()) out.warnings.push_back(file + ": ignores the optional extensions " + ignored);
  }

  // images: those that did not load (a missing file is only a warning for tinygltf) stay empty
  for (size_t i = 0; i < m.images.size(); ++i) {
    const tinygltf::Image& img = m.images[i];
    GltfImage g;
    g.name = !img.name.empty() ? img.name : !img.uri.empty() && img.uri.rfind("data:", 0) != 0 ? img.uri : "image " + std::to_string(i);
    if (img.component == 4 && img.bits == 8 && img.image.size() == static_cast<size_t>(img.width) * img.height * 4) {
      g.width = img.width;
      g.height = img.height;
      g.rgba = img.image;
    }
    out.images.push_back(std::move(g));
  }
  std::vector<uint8_t> used_images(out.images.size(), 0);
  auto texture_ref = [&](int texture, int tex_coord, const tinygltf::ExtensionMap& ext, const std::string& what) {
    GltfTextureRef t;
    if (texture < 0) return t;
    if (texture >= static_cast<int>(m.textures.size())) r.fail(what + " names texture " + std::to_string(texture) + ", which does not exist");
    const tinygltf::Texture& tex = m.textures[static_cast<size_t>(texture)];
    if (tex.source < 0 || tex.source >= static_cast<int>(out.images.size())) {
      r.fail(what + ": texture " + std::to_string(texture) + " has no image this reader can use (its source is " + std::to_string(tex.source) + ")");
    }
    const GltfImage& img = out.images[static_cast<size_t>(tex.source)];
    used_images[static_cast<size_t>(tex.source)] = 1;
    if (img.rgba.empty()) r.fail(what + ": image " + std::to_string(tex.source) + " ('" + img.name + "') is missing or cannot be decoded");
    t.image = tex.source;
    t.tex_coord = tex_coord;
    if (tex.sampler >= 0) {
      if (tex.sampler >= static_cast<int>(m.samplers.size())) r.fail(what + ": texture " + std::to_string(texture) + " names a sampler that does not exist");
      const tinygltf::Sampler& s = m.samplers[static_cast<size_t>(tex.sampler)];
      t.sampler.wrap_s = wrap_of(s.wrapS);
      t.sampler.wrap_t = wrap_of(s.wrapT);
      t.sampler.mag_linear = s.magFilter != TINYGLTF_TEXTURE_FILTER_NEAREST;
      switch (s.minFilter) {
        case TINYGLTF_TEXTURE_FILTER_NEAREST: t.sampler.min_linear = false; t.sampler.mipmaps = false; break;
        case TINYGLTF_TEXTURE_FILTER_LINEAR: t.sampler.mipmaps = false; break;
        case TINYGLTF_TEXTURE_FILTER_NEAREST_MIPMAP_NEAREST: t.sampler.min_linear = false; t.sampler.mip_linear = false; break;
        case TINYGLTF_TEXTURE_FILTER_LINEAR_MIPMAP_NEAREST: t.sampler.mip_linear = false; break;
        case TINYGLTF_TEXTURE_FILTER_NEAREST_MIPMAP_LINEAR: t.sampler.min_linear = false; break;
        default: break;  // LINEAR_MIPMAP_LINEAR, and unspecified
      }
    }
    const auto tt = ext.find("KHR_texture_transform");
    if (tt != ext.end()) {
      const tinygltf::Value& v = tt->second;
      glm::vec2 offset(0.0f), scale(1.0f);
      float rotation = 0.0f;
      auto vec2 = [&](const char* key, glm::vec2& into) {
        if (!v.Has(key)) return;
        const tinygltf::Value& a = v.Get(key);
        if (!a.IsArray() || a.ArrayLen() != 2) r.fail(what + ": KHR_texture_transform " + key + " must hold 2 numbers");
        for (int k = 0; k < 2; ++k) into[k] = to_float(a.Get(k).GetNumberAsDouble(), file, what + " KHR_texture_transform " + key);
      };
      vec2("offset", offset);
      vec2("scale", scale);
      if (v.Has("rotation")) rotation = to_float(v.Get("rotation").GetNumberAsDouble(), file, what + " KHR_texture_transform rotation");
      if (v.Has("texCoord")) t.tex_coord = v.Get("texCoord").GetNumberAsInt();
      // T * R * S as the extension defines them (column-major mat3 acting on (u, v, 1))
      const float c = std::cos(rotation), sn = std::sin(rotation);
      const glm::mat3 T(1, 0, 0, 0, 1, 0, offset.x, offset.y, 1);
      const glm::mat3 R(c, -sn, 0, sn, c, 0, 0, 0, 1);
      const glm::mat3 S(scale.x, 0, 0, 0, scale.y, 0, 0, 0, 1);
      t.transform = T * R * S;
    }
    if (t.tex_coord < 0 || t.tex_coord > 1) r.fail(what + ": texCoord " + std::to_string(t.tex_coord) + " (this reader takes sets 0 and 1)");
    return t;
  };

  out.materials.emplace_back();  // default
  for (const tinygltf::Material& mat : m.materials) {
    GltfMaterial g;
    g.name = mat.name;
    g.pbr = true;
    const auto& pbr = mat.pbrMetallicRoughness;
    const std::string at = "material '" + mat.name + "'";
    if (pbr.baseColorFactor.size() == 4) {
      g.base_color = to_floats<glm::vec3>(pbr.baseColorFactor, file, at + " baseColorFactor");
      g.alpha = to_float(pbr.baseColorFactor[3], file, at + " alpha");
    }
    g.base_color_texture = texture_ref(pbr.baseColorTexture.index, pbr.baseColorTexture.texCoord, pbr.baseColorTexture.extensions, at + " baseColorTexture");
    g.metallic = to_float(pbr.metallicFactor, file, at + " metallicFactor");
    g.roughness = to_float(pbr.roughnessFactor, file, at + " roughnessFactor");
    g.metallic_roughness_texture = texture_ref(pbr.metallicRoughnessTexture.index, pbr.metallicRoughnessTexture.texCoord,
                                               pbr.metallicRoughnessTexture.extensions, at + " metallicRoughnessTexture");
    g.normal_texture = texture_ref(mat.normalTexture.index, mat.normalTexture.texCoord, mat.normalTexture.extensions, at + " normalTexture");
    g.normal_texture.scale = to_float(mat.normalTexture.scale, file, at + " normalTexture scale");
    g.occlusion_texture = texture_ref(mat.occlusionTexture.index, mat.occlusionTexture.texCoord, mat.occlusionTexture.extensions, at + " occlusionTexture");
    g.occlusion_texture.scale = to_float(mat.occlusionTexture.strength, file, at + " occlusionTexture strength");
    if (mat.emissiveFactor.size() == 3) g.emissive = to_floats<glm::vec3>(mat.emissiveFactor, file, at + " emissiveFactor");
    g.emissive_texture = texture_ref(mat.emissiveTexture.index, mat.emissiveTexture.texCoord, mat.emissiveTexture.extensions, at + " emissiveTexture");
    g.alpha_mode = mat.alphaMode == "MASK" ? AlphaMode::kMask : mat.alphaMode == "BLEND" ? AlphaMode::kBlend : AlphaMode::kOpaque;
    if (mat.alphaMode != "OPAQUE" && mat.alphaMode != "MASK" && mat.alphaMode != "BLEND") r.fail(at + ": unknown alphaMode " + quote_token(mat.alphaMode));
    g.alpha_cutoff = to_float(mat.alphaCutoff, file, at + " alphaCutoff");
    g.double_sided = mat.doubleSided;
    const auto t = mat.extensions.find("KHR_materials_transmission");
    if (t != mat.extensions.end() && t->second.Has("transmissionFactor")) {
      g.transmission = to_float(t->second.Get("transmissionFactor").GetNumberAsDouble(), file, at + " transmissionFactor");
    }
    const auto i = mat.extensions.find("KHR_materials_ior");
    if (i != mat.extensions.end() && i->second.Has("ior")) g.ior = to_float(i->second.Get("ior").GetNumberAsDouble(), file, at + " ior");
    // Factors outside glTF's ranges were used as given (a metallic factor of 5 gave back five times
    // the light): each is taken at its range's nearest bound, with a warning.
    // `unit`: the range is 0-1, else 0 and more
    auto bounded = [&](float& v, const char* what, bool unit) {
      const float b = unit ? std::clamp(v, 0.0f, 1.0f) : std::max(v, 0.0f);
      if (b == v) return;
      std::ostringstream w;
      w << file << ": " << at << " " << what << " " << v << (unit ? " lies outside 0-1" : " lies below 0") << " (glTF's range): taken as " << b;
      out.warnings.push_back(w.str());
      v = b;
    };
    for (int k = 0; k < 3; ++k) bounded(g.base_color[k], "baseColorFactor", true);
    bounded(g.alpha, "alpha", true);
    bounded(g.metallic, "metallicFactor", true);
    bounded(g.roughness, "roughnessFactor", true);
    bounded(g.occlusion_texture.scale, "occlusionTexture strength", true);
    for (int k = 0; k < 3; ++k) bounded(g.emissive[k], "emissiveFactor", false);
    bounded(g.transmission, "transmissionFactor", true);
    if (g.ior != 0.0f && !(g.ior >= 1.0f)) {
      std::ostringstream w;
      w << file << ": " << at << " ior " << g.ior << " is neither 0 nor 1 or more (KHR_materials_ior): taken as 1.5";
      out.warnings.push_back(w.str());
      g.ior = 1.5f;
    }
    const auto es = mat.extensions.find("KHR_materials_emissive_strength");
    if (es != mat.extensions.end() && es->second.Has("emissiveStrength")) {
      float strength = to_float(es->second.Get("emissiveStrength").GetNumberAsDouble(), file, at + " emissiveStrength");
      bounded(strength, "emissiveStrength", false);
      g.emissive *= strength;
    }
    out.materials.push_back(g);
  }
  for (size_t i = 0; i < out.images.size(); ++i) {
    if (out.images[i].rgba.empty() && !used_images[i]) {
      out.warnings.push_back(file + ": image " + std::to_string(i) + " ('" + out.images[i].name +
                             "') is missing or cannot be decoded; no material uses it");
    }
  }

  for (size_t mi = 0; mi < m.meshes.size(); ++mi) {
    const tinygltf::Mesh& mesh = m.meshes[mi];
    GltfMesh gm;
    const std::string mname = "mesh '" + (mesh.name.empty() ? std::to_string(mi) : mesh.name) + "'";
    bool any_skinned = false, any_plain = false;
    size_t targets = 0;
    for (const tinygltf::Primitive& prim : mesh.primitives) targets = std::max(targets, prim.targets.size());
    gm.targets.resize(targets);
    // first pass: which attributes any primitive has, so every vertex gets them
    bool has_uv[2] = {false, false}, has_color = false, has_normal = false, has_tangent = false, target_normals = false;
    int sets = 0;
    for (const tinygltf::Primitive& prim : mesh.primitives) {
      has_uv[0] |= prim.attributes.count("TEXCOORD_0") > 0;
      has_uv[1] |= prim.attributes.count("TEXCOORD_1") > 0;
      has_color |= prim.attributes.count("COLOR_0") > 0;
      has_normal |= prim.attributes.count("NORMAL") > 0;
      has_tangent |= prim.attributes.count("TANGENT") > 0;
      for (const auto& tg : prim.targets) target_normals |= tg.count("NORMAL") > 0;
      int s = 0;
      while (prim.attributes.count("JOINTS_" + std::to_string(s))) ++s;
      sets = std::max(sets, s);
    }
    gm.influence_sets = sets;
    for (size_t pi = 0; pi < mesh.primitives.size(); ++pi) {
      const tinygltf::Primitive& prim = mesh.primitives[pi];
      const std::string where = mname + " primitive " + std::to_string(pi);
      const int mode = prim.mode < 0 ? TINYGLTF_MODE_TRIANGLES : prim.mode;
      if (mode != TINYGLTF_MODE_TRIANGLES && mode != TINYGLTF_MODE_TRIANGLE_STRIP && mode != TINYGLTF_MODE_TRIANGLE_FAN) {
        static const char* kModes[] = {"POINTS", "LINES", "LINE_LOOP", "LINE_STRIP"};
        out.warnings.push_back(file + ": " + where + " draws " + (mode >= 0 && mode < 4 ? kModes[mode] : "mode " + std::to_string(mode)) +
                               ", which is not rendered (skipped)");
        continue;
      }
      const auto pos_it = prim.attributes.find("POSITION");
      if (pos_it == prim.attributes.end()) r.fail(where + " has no POSITION");
      const std::vector<float> pos = r.floats(pos_it->second, 3, where + " POSITION");
      const size_t nv = pos.size() / 3;
      std::vector<uint32_t> idx;
      if (prim.indices >= 0) {
        idx = r.indices(prim.indices, where + " indices");
      } else {
        idx.resize(nv);
        for (uint32_t k = 0; k < nv; ++k) idx[k] = k;
      }
      for (const uint32_t k : idx) {
        if (k >= nv) r.fail(where + ": index " + std::to_string(k) + " past its " + std::to_string(nv) + " vertices");
      }
      // the primitive's triangles, in its own vertex numbering
      std::vector<glm::uvec3> tri;
      if (mode == TINYGLTF_MODE_TRIANGLES) {
        if (idx.size() % 3) r.fail(where + ": index count " + std::to_string(idx.size()) + " is not a multiple of 3");
        for (size_t k = 0; k + 2 < idx.size(); k += 3) tri.emplace_back(idx[k], idx[k + 1], idx[k + 2]);
      } else if (mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
        // glTF 2.0, 3.7.2.1: triangle i is (i, i + 1 + i % 2, i + 2 - i % 2), keeping the winding
        for (size_t k = 0; k + 2 < idx.size(); ++k) tri.emplace_back(idx[k], idx[k + 1 + k % 2], idx[k + 2 - k % 2]);
      } else {
        for (size_t k = 1; k + 1 < idx.size(); ++k) tri.emplace_back(idx[k], idx[k + 1], idx[0]);
      }
      const uint32_t material = prim.material >= 0 ? static_cast<uint32_t>(prim.material + 1) : 0u;
      if (material >= out.materials.size()) r.fail(where + " names material " + std::to_string(prim.material) + ", which does not exist");

      // per-vertex attributes of the primitive
      auto attribute = [&](const char* name, int comps) {
        const auto it = prim.attributes.find(name);
        if (it == prim.attributes.end()) return std::vector<float>();
        std::vector<float> v = r.floats(it->second, comps, where + " " + name);
        if (v.size() != nv * static_cast<size_t>(comps)) r.fail(where + ": " + name + " count differs from POSITION");
        return v;
      };
      const std::vector<float> normal = attribute("NORMAL", 3), tangent = attribute("TANGENT", 4);
      std::vector<float> uv[2] = {attribute("TEXCOORD_0", 2), attribute("TEXCOORD_1", 2)};
      std::vector<float> color;
      if (const auto c = prim.attributes.find("COLOR_0"); c != prim.attributes.end()) {
        const tinygltf::Accessor& a = m.accessors.at(static_cast<size_t>(c->second));
        const int comps = a.type == TINYGLTF_TYPE_VEC3 ? 3 : 4;
        const std::vector<float> raw = attribute("COLOR_0", comps);
        color.resize(nv * 4, 1.0f);
        for (size_t k = 0; k < nv; ++k)
          for (int ch = 0; ch < comps; ++ch) color[4 * k + ch] = raw[comps * k + ch];
      }
      int psets = 0;
      while (prim.attributes.count("JOINTS_" + std::to_string(psets))) ++psets;
      for (int s = 0; s < psets; ++s) {
        if (!prim.attributes.count("WEIGHTS_" + std::to_string(s))) r.fail(where + " has JOINTS_" + std::to_string(s) + " without WEIGHTS_" + std::to_string(s));
      }
      if (psets == 0 && prim.attributes.count("WEIGHTS_0")) r.fail(where + " has WEIGHTS_0 without JOINTS_0");
      (psets > 0 ? any_skinned : any_plain) = true;

      // vertices: shared as the file shares them, or one per triangle corner where the primitive
      // has no normals but others do (flat normals then need their own vertices)
      const bool flat = has_normal && normal.empty();
      std::vector<uint32_t> source;  // the primitive vertex each new vertex copies
      if (flat) {
        for (const glm::uvec3& t : tri) source.insert(source.end(), {t.x, t.y, t.z});
      } else {
        source.resize(nv);
        for (uint32_t k = 0; k < nv; ++k) source[k] = k;
      }
      const uint32_t base = static_cast<uint32_t>(gm.positions.size());
      auto p3 = [&](const std::vector<float>& v, uint32_t k) { return glm::vec3(v[3 * k], v[3 * k + 1], v[3 * k + 2]); };
      for (size_t n = 0; n < source.size(); ++n) {
        const uint32_t k = source[n];
        gm.positions.push_back(p3(pos, k));
        if (has_normal) {
          if (!flat) {
            gm.normals.push_back(p3(normal, k));
          } else {
            const glm::uvec3& t = tri[n / 3];
            const glm::vec3 f = glm::cross(p3(pos, t.y) - p3(pos, t.x), p3(pos, t.z) - p3(pos, t.x));
            const float len = glm::length(f);
            gm.normals.push_back(len > 0.0f ? f / len : glm::vec3(0.0f, 0.0f, 1.0f));
          }
        }
        if (has_tangent) gm.tangents.push_back(tangent.empty() ? glm::vec4(0.0f) : glm::vec4(p3(tangent, k), tangent[4 * k + 3]));
        for (int s = 0; s < 2; ++s) {
          if (has_uv[s]) gm.uv[s].push_back(uv[s].empty() ? glm::vec2(0.0f) : glm::vec2(uv[s][2 * k], uv[s][2 * k + 1]));
        }
        if (has_color) gm.colors.push_back(color.empty() ? glm::vec4(1.0f) : glm::vec4(color[4 * k], color[4 * k + 1], color[4 * k + 2], color[4 * k + 3]));
      }
      if (sets > 0) {
        for (int s = 0; s < sets; ++s) {
          std::vector<float> j, w;
          if (s < psets) {
            j = attribute(("JOINTS_" + std::to_string(s)).c_str(), 4);
            w = attribute(("WEIGHTS_" + std::to_string(s)).c_str(), 4);
          }
          for (size_t n = 0; n < source.size(); ++n) {
            const uint32_t k = source[n];
            const size_t v = base + n;
            if (gm.joints.size() < (v + 1) * sets) {
              gm.joints.resize((v + 1) * sets, glm::uvec4(0));
              gm.weights.resize((v + 1) * sets, glm::vec4(0.0f));
            }
            if (!j.empty()) {
              for (int c = 0; c < 4; ++c) {
                if (!(j[4 * k + c] >= 0.0f) || j[4 * k + c] > 65535.0f) r.fail(where + ": JOINTS_" + std::to_string(s) + " holds an invalid joint index");
              }
              gm.joints[v * sets + s] = glm::uvec4(j[4 * k], j[4 * k + 1], j[4 * k + 2], j[4 * k + 3]);
              gm.weights[v * sets + s] = glm::vec4(w[4 * k], w[4 * k + 1], w[4 * k + 2], w[4 * k + 3]);
            }
          }
        }
      }
      // morph targets: deltas per new vertex
      for (size_t ti = 0; ti < targets; ++ti) {
        GltfMorphTarget& target = gm.targets[ti];
        std::vector<float> dp, dn;
        if (ti < prim.targets.size()) {
          const auto& tg = prim.targets[ti];
          const std::string tw = where + " target " + std::to_string(ti);
          if (const auto it = tg.find("POSITION"); it != tg.end()) dp = r.floats(it->second, 3, tw + " POSITION");
          if (const auto it = tg.find("NORMAL"); it != tg.end()) dn = r.floats(it->second, 3, tw + " NORMAL");
          if ((!dp.empty() && dp.size() != 3 * nv) || (!dn.empty() && dn.size() != 3 * nv)) r.fail(tw + ": count differs from POSITION");
        }
        for (size_t n = 0; n < source.size(); ++n) {
          const uint32_t k = source[n];
          target.position.push_back(dp.empty() ? glm::vec3(0.0f) : p3(dp, k));
          if (target_normals) target.normal.push_back(dn.empty() ? glm::vec3(0.0f) : p3(dn, k));
        }
      }
      for (size_t t = 0; t < tri.size(); ++t) {
        const glm::uvec3 v = flat ? glm::uvec3(base + 3 * t, base + 3 * t + 1, base + 3 * t + 2) : glm::uvec3(base) + tri[t];
        gm.indices.push_back(v);
        gm.material.push_back(material);
      }
    }
    if (any_skinned && any_plain) r.fail(mname + " mixes skinned and unskinned primitives");
    gm.default_weights.assign(targets, 0.0f);
    for (size_t k = 0; k < mesh.weights.size() && k < targets; ++k) gm.default_weights[k] = to_float(mesh.weights[k], file, mname + " weights");
    out.meshes.push_back(std::move(gm));
  }
  // bind-pose triangles, with the default morph weights applied
  for (size_t mi = 0; mi < out.meshes.size(); ++mi) {
    GltfMesh& gm = out.meshes[mi];
    const std::vector<glm::vec3> p = gm.morphed() ? out.morphed_positions(static_cast<int>(mi), gm.default_weights) : gm.positions;
    for (const glm::uvec3& t : gm.indices) gm.tris.push_back({p[t.x], p[t.y], p[t.z]});
  }

  // nodes: order parents before children (glTF does not promise it)
  std::vector<int> parent(m.nodes.size(), -1);
  for (size_t i = 0; i < m.nodes.size(); ++i) {
    for (const int c : m.nodes[i].children) {
      if (c < 0 || c >= static_cast<int>(m.nodes.size()) || parent[static_cast<size_t>(c)] != -1) {
        throw ParseError(file, 0, 0, "node " + std::to_string(c) + " has two parents or does not exist");
      }
      parent[static_cast<size_t>(c)] = static_cast<int>(i);
    }
  }
  std::vector<int> order, new_index(m.nodes.size(), -1);
  std::function<void(int)> visit = [&](int n) {
    if (order.size() > m.nodes.size()) throw ParseError(file, 0, 0, "the node hierarchy has a cycle");
    new_index[static_cast<size_t>(n)] = static_cast<int>(order.size());
    order.push_back(n);
    for (const int c : m.nodes[static_cast<size_t>(n)].children) visit(c);
  };
  for (size_t i = 0; i < m.nodes.size(); ++i) {
    if (parent[i] == -1) visit(static_cast<int>(i));
  }
  if (order.size() != m.nodes.size()) throw ParseError(file, 0, 0, "the node hierarchy has a cycle");
  for (const int n : order) {
    const tinygltf::Node& src = m.nodes[static_cast<size_t>(n)];
    GltfNode g;
    g.name = src.name;
    g.parent = parent[static_cast<size_t>(n)] >= 0 ? new_index[static_cast<size_t>(parent[static_cast<size_t>(n)])] : -1;
    g.mesh = src.mesh;
    if (g.mesh >= static_cast<int>(out.meshes.size())) throw ParseError(file, 0, 0, "node '" + src.name + "' names a mesh that does not exist");
    g.skin = src.skin;
    if (g.skin >= static_cast<int>(m.skins.size())) throw ParseError(file, 0, 0, "node '" + src.name + "' names a skin that does not exist");
    if (g.skin >= 0 && (g.mesh < 0 || !out.meshes[static_cast<size_t>(g.mesh)].skinned())) {
      throw ParseError(file, 0, 0, "node '" + src.name + "' has a skin but no mesh with JOINTS_0/WEIGHTS_0");
    }
    if (src.matrix.size() == 16) {
      g.has_matrix = true;
      for (int k = 0; k < 16; ++k) glm::value_ptr(g.matrix)[k] = to_float(src.matrix[static_cast<size_t>(k)], file, "node '" + src.name + "' matrix");
    }
    if (src.translation.size() == 3) g.translation = to_floats<glm::vec3>(src.translation, file, "node '" + src.name + "' translation");
    if (src.rotation.size() == 4) {
      const glm::vec4 q = to_floats<glm::vec4>(src.rotation, file, "node '" + src.name + "' rotation");
      g.rotation = glm::quat(q.w, q.x, q.y, q.z);
    }
    if (src.scale.size() == 3) g.scale = to_floats<glm::vec3>(src.scale, file, "node '" + src.name + "' scale");
    for (const double w : src.weights) g.weights.push_back(to_float(w, file, "node '" + src.name + "' weights"));
    out.nodes.push_back(g);
  }
  for (const tinygltf::Skin& sk : m.skins) {
    GltfSkin gs;
    gs.name = sk.name;
    for (const int j : sk.joints) {
      if (j < 0 || j >= static_cast<int>(m.nodes.size())) throw ParseError(file, 0, 0, "skin '" + sk.name + "' names joint node " + std::to_string(j) + ", which does not exist");
      gs.joints.push_back(new_index[static_cast<size_t>(j)]);
    }
    if (sk.inverseBindMatrices >= 0) {
      const std::vector<float> ib = r.floats(sk.inverseBindMatrices, 16, "skin '" + sk.name + "' inverseBindMatrices");
      if (ib.size() != 16 * gs.joints.size()) throw ParseError(file, 0, 0, "skin '" + sk.name + "': inverseBindMatrices count differs from its joints");
      for (size_t k = 0; k < gs.joints.size(); ++k) gs.inverse_bind.push_back(glm::make_mat4(&ib[16 * k]));
    } else {
      gs.inverse_bind.assign(gs.joints.size(), glm::mat4(1.0f));
    }
    out.skins.push_back(std::move(gs));
  }
  for (const GltfNode& n : out.nodes) {
    if (n.skin < 0) continue;
    const size_t joints = out.skins[static_cast<size_t>(n.skin)].joints.size();
    for (const glm::uvec4& j : out.meshes[static_cast<size_t>(n.mesh)].joints) {
      if (j.x >= joints || j.y >= joints || j.z >= joints || j.w >= joints) {
        throw ParseError(file, 0, 0, "node '" + n.name + "': a vertex names joint " + std::to_string(std::max({j.x, j.y, j.z, j.w})) + " of a skin with " +
                                         std::to_string(joints));
      }
    }
  }
  for (const tinygltf::Animation& a : m.animations) {
    GltfAnimation ga;
    ga.name = a.name;
    const std::string an = "animation '" + a.name + "'";
    for (const tinygltf::AnimationChannel& ch : a.channels) {
      if (ch.target_node < 0 || ch.target_node >= static_cast<int>(m.nodes.size())) throw ParseError(file, 0, 0, an + " targets a node that does not exist");
      if (ch.sampler < 0 || ch.sampler >= static_cast<int>(a.samplers.size())) throw ParseError(file, 0, 0, an + " names a sampler that does not exist");
      const tinygltf::AnimationSampler& s = a.samplers[static_cast<size_t>(ch.sampler)];
      GltfChannel c;
      c.node = new_index[static_cast<size_t>(ch.target_node)];
      if (ch.target_path == "translation") c.path = GltfChannel::kTranslation;
      else if (ch.target_path == "rotation") c.path = GltfChannel::kRotation;
      else if (ch.target_path == "scale") c.path = GltfChannel::kScale;
      else if (ch.target_path == "weights") c.path = GltfChannel::kWeights;
      else throw ParseError(file, 0, 0, an + ": unknown target path " + quote_token(ch.target_path));
      c.interpolation = s.interpolation == "STEP" ? GltfChannel::kStep : s.interpolation == "CUBICSPLINE" ? GltfChannel::kCubic : GltfChannel::kLinear;
      c.times = r.floats(s.input, 1, an + " input");
      const size_t per_key = c.interpolation == GltfChannel::kCubic ? 3 : 1;
      if (c.path == GltfChannel::kWeights) {
        const GltfNode& node = out.nodes[static_cast<size_t>(c.node)];
        if (node.mesh < 0 || !out.meshes[static_cast<size_t>(node.mesh)].morphed()) throw ParseError(file, 0, 0, an + " animates the weights of a node without morph targets");
        c.weight_count = static_cast<int>(out.meshes[static_cast<size_t>(node.mesh)].targets.size());
        c.weights = r.floats(s.output, 1, an + " output");
        if (c.times.empty() || c.weights.size() != c.times.size() * per_key * static_cast<size_t>(c.weight_count)) {
          throw ParseError(file, 0, 0, an + ": sampler input and output counts do not match");
        }
      } else {
        const int comps = c.path == GltfChannel::kRotation ? 4 : 3;
        const std::vector<float> v = r.floats(s.output, comps, an + " output");
        for (size_t k = 0; k + comps <= v.size(); k += static_cast<size_t>(comps)) {
          c.values.push_back(glm::vec4(v[k], v[k + 1], v[k + 2], comps == 4 ? v[k + 3] : 0.0f));
        }
        if (c.times.empty() || c.values.size() != c.times.size() * per_key) throw ParseError(file, 0, 0, an + ": sampler input and output counts do not match");
      }
      for (size_t k = 1; k < c.times.size(); ++k) {
        if (!(c.times[k] > c.times[k - 1])) throw ParseError(file, 0, 0, an + ": key times must increase");
      }
      ga.duration_s = std::max(ga.duration_s, c.times.back());
      ga.channels.push_back(std::move(c));
    }
    out.animations.push_back(std::move(ga));
  }
  return out;
}

namespace {

/// The key interval around t: index i and the fraction s in it; false before the first key or after
/// the last (then `i` is that key).
bool key_interval(const std::vector<float>& k, float t, size_t& i, float& s, float& dt) {
  if (t <= k.front()) {
    i = 0;
    return false;
  }
  if (t >= k.back()) {
    i = k.size() - 1;
    return false;
  }
  i = static_cast<size_t>(std::upper_bound(k.begin(), k.end(), t) - k.begin()) - 1;
  dt = k[i + 1] - k[i];
  s = (t - k[i]) / dt;
  return true;
}

glm::vec4 sample(const GltfChannel& c, float t) {
  const bool cubic = c.interpolation == GltfChannel::kCubic;
  auto value = [&](size_t i) { return cubic ? c.values[3 * i + 1] : c.values[i]; };
  size_t i;
  float s = 0.0f, dt = 0.0f;
  if (!key_interval(c.times, t, i, s, dt)) return value(i);
  if (c.interpolation == GltfChannel::kStep) return value(i);
  if (cubic) {
    // glTF 2.0 spec, appendix C: Hermite with tangents scaled by the key interval
    const glm::vec4 p0 = c.values[3 * i + 1], m0 = dt * c.values[3 * i + 2];
    const glm::vec4 p1 = c.values[3 * (i + 1) + 1], m1 = dt * c.values[3 * (i + 1)];
    const float s2 = s * s, s3 = s2 * s;
    glm::vec4 r = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1;
    if (c.path == GltfChannel::kRotation) r = glm::normalize(r);
    return r;
  }
  if (c.path == GltfChannel::kRotation) {
    const glm::quat a(c.values[i].w, c.values[i].x, c.values[i].y, c.values[i].z);
    const glm::quat b(c.values[i + 1].w, c.values[i + 1].x, c.values[i + 1].y, c.values[i + 1].z);
    const glm::quat q = glm::slerp(a, b, s);
    return glm::vec4(q.x, q.y, q.z, q.w);
  }
  return glm::mix(c.values[i], c.values[i + 1], s);
}

std::vector<float> sample_weights(const GltfChannel& c, float t) {
  const size_t n = static_cast<size_t>(c.weight_count);
  const bool cubic = c.interpolation == GltfChannel::kCubic;
  // element e of key i's value (cubic: in-tangent, value, out-tangent blocks of n)
  auto at = [&](size_t i, size_t part, size_t e) { return cubic ? c.weights[(3 * i + part) * n + e] : c.weights[i * n + e]; };
  std::vector<float> w(n);
  size_t i;
  float s = 0.0f, dt = 0.0f;
  const bool inside = key_interval(c.times, t, i, s, dt);
  for (size_t e = 0; e < n; ++e) {
    if (!inside || c.interpolation == GltfChannel::kStep) {
      w[e] = at(i, 1, e);
    } else if (cubic) {
      const float p0 = at(i, 1, e), m0 = dt * at(i, 2, e), p1 = at(i + 1, 1, e), m1 = dt * at(i + 1, 0, e);
      const float s2 = s * s, s3 = s2 * s;
      w[e] = (2 * s3 - 3 * s2 + 1) * p0 + (s3 - 2 * s2 + s) * m0 + (-2 * s3 + 3 * s2) * p1 + (s3 - s2) * m1;
    } else {
      w[e] = at(i, 1, e) + s * (at(i + 1, 1, e) - at(i, 1, e));
    }
  }
  return w;
}

float clip_time(const GltfAnimation& a, float t) { return a.duration_s > 0.0f ? std::fmod(std::fmax(t, 0.0f), a.duration_s) : 0.0f; }

}  // namespace

std::vector<glm::mat4> GltfModel::node_transforms(int clip, float t) const {
  std::vector<glm::vec3> tr(nodes.size()), sc(nodes.size());
  std::vector<glm::quat> rot(nodes.size());
  for (size_t i = 0; i < nodes.size(); ++i) {
    tr[i] = nodes[i].translation;
    rot[i] = nodes[i].rotation;
    sc[i] = nodes[i].scale;
  }
  if (clip >= 0 && clip < static_cast<int>(animations.size())) {
    const GltfAnimation& a = animations[static_cast<size_t>(clip)];
    const float local = clip_time(a, t);
    for (const GltfChannel& c : a.channels) {
      if (c.path == GltfChannel::kWeights) continue;
      const glm::vec4 v = sample(c, local);
      if (c.path == GltfChannel::kTranslation) tr[static_cast<size_t>(c.node)] = glm::vec3(v);
      else if (c.path == GltfChannel::kScale) sc[static_cast<size_t>(c.node)] = glm::vec3(v);
      else rot[static_cast<size_t>(c.node)] = glm::normalize(glm::quat(v.w, v.x, v.y, v.z));
    }
  }
  std::vector<glm::mat4> world(nodes.size());
  for (size_t i = 0; i < nodes.size(); ++i) {
    const glm::mat4 local = nodes[i].has_matrix ? nodes[i].matrix
                                                : glm::translate(glm::mat4(1.0f), tr[i]) * glm::mat4_cast(rot[i]) * glm::scale(glm::mat4(1.0f), sc[i]);
    world[i] = nodes[i].parent >= 0 ? world[static_cast<size_t>(nodes[i].parent)] * local : local;
  }
  return world;
}

std::vector<std::vector<float>> GltfModel::node_weights(int clip, float t) const {
  std::vector<std::vector<float>> w(nodes.size());
  for (size_t i = 0; i < nodes.size(); ++i) {
    if (nodes[i].mesh < 0 || !meshes[static_cast<size_t>(nodes[i].mesh)].morphed()) continue;
    const GltfMesh& m = meshes[static_cast<size_t>(nodes[i].mesh)];
    w[i] = m.default_weights;
    for (size_t k = 0; k < nodes[i].weights.size() && k < w[i].size(); ++k) w[i][k] = nodes[i].weights[k];
  }
  if (clip >= 0 && clip < static_cast<int>(animations.size())) {
    const GltfAnimation& a = animations[static_cast<size_t>(clip)];
    for (const GltfChannel& c : a.channels) {
      if (c.path == GltfChannel::kWeights) w[static_cast<size_t>(c.node)] = sample_weights(c, clip_time(a, t));
    }
  }
  return w;
}

std::vector<glm::vec3> GltfModel::morphed_positions(int mesh, const std::vector<float>& weights, std::vector<glm::vec3>* normals) const {
  const GltfMesh& m = meshes.at(static_cast<size_t>(mesh));
  std::vector<glm::vec3> p = m.positions;
  if (normals) *normals = m.normals;
  for (size_t t = 0; t < m.targets.size() && t < weights.size(); ++t) {
    const float w = weights[t];
    if (w == 0.0f) continue;
    const GltfMorphTarget& target = m.targets[t];
    for (size_t v = 0; v < p.size(); ++v) p[v] += w * target.position[v];
    if (normals && !normals->empty() && !target.normal.empty()) {
      for (size_t v = 0; v < normals->size(); ++v) (*normals)[v] += w * target.normal[v];
    }
  }
  return p;
}

std::vector<glm::vec3> GltfModel::skinned_positions(int mesh, int skin, const std::vector<glm::mat4>& node_world,
                                                    const std::vector<glm::vec3>* base, std::vector<glm::vec3>* normals) const {
  const GltfMesh& m = meshes.at(static_cast<size_t>(mesh));
  const GltfSkin& s = skins.at(static_cast<size_t>(skin));
  const std::vector<glm::vec3>& in = base ? *base : m.positions;
  std::vector<glm::mat4> joint(s.joints.size());
  for (size_t j = 0; j < joint.size(); ++j) joint[j] = node_world.at(static_cast<size_t>(s.joints[j])) * s.inverse_bind[j];
  const size_t sets = static_cast<size_t>(m.influence_sets);
  std::vector<glm::vec3> out(in.size());
  for (size_t v = 0; v < out.size(); ++v) {
    glm::mat4 blend(0.0f);
    float sum = 0.0f;
    for (size_t k = 0; k < sets; ++k) {
      const glm::vec4 w = m.weights[v * sets + k];
      const glm::uvec4 j = m.joints[v * sets + k];
      for (int c = 0; c < 4; ++c) {
        if (w[c] == 0.0f) continue;
        blend += w[c] * joint[j[c]];
        sum += w[c];
      }
    }
    if (!(sum > 0.0f)) {
      out[v] = in[v];  // no weights: the bind pose
      continue;
    }
    blend /= sum;
    out[v] = glm::vec3(blend * glm::vec4(in[v], 1.0f));
    if (normals && v < normals->size()) {
      const glm::vec3 n = glm::transpose(glm::inverse(glm::mat3(blend))) * (*normals)[v];
      const float len = glm::length(n);
      if (len > 0.0f) (*normals)[v] = n / len;
    }
  }
  return out;
}

size_t GltfModel::triangle_count() const {
  size_t n = 0;
  for (const GltfMesh& m : meshes) n += m.tris.size();
  return n;
}

}  // namespace artrace::io
